"""The fluids' volume ratio J inside the water, watched at every sample of a validation case.

The fluid-density issue's "J stays bounded": no fluid particle 2 h or more inside the water has J outside
[0.5, 2] at any sample. Inside means at least 2 h from the walls (their signed distance) and no empty cell within
two cells of the particle's own (a cell inside the walls that holds no particle is air: the free surface or a
gap). The suite watches every simulation a case runs through :func:`augmpm.validation.common.simulate` and the
cases' own sampling loops, and adds the extremes to the case's records (:func:`records`): judged for the default
density, reported for the variants a case runs beside it. A packing fluid's J stops at 1.25 by construction
(``MAX_DILATION``), so for it only the lower bound says anything.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from augmpm.scene import Fluid
from augmpm.simulation import Simulation
from augmpm.validation.records import Record

#: The range J must stay in (1).
LOW, HIGH = 0.5, 2.0
#: How deep inside the water a particle is watched (cells).
DEPTH = 2
#: The fluids' density estimate when a scene names none: the variant whose J the suite judges.
DEFAULT_DENSITY = Fluid.model_fields["density_estimate"].default


@dataclass
class _Extremes:
    low: float = math.inf
    high: float = -math.inf


#: The extremes seen since :func:`reset` (this process's case), per method and the fluids' density estimates.
_SEEN: dict[tuple[str, str], _Extremes] = {}


def reset() -> None:
    """Forgets what was seen (a new case starts)."""
    _SEEN.clear()


def _density_estimates(sim: Simulation) -> str:
    """The fluids' ``density_estimate`` values in ``sim``'s scene, joined by ``+`` (the variant a case runs)."""
    fluids = [body.material for body in sim.scene.bodies if body.material.type == "fluid"]
    return "+".join(sorted({material.density_estimate for material in fluids}))


def watch(sim: Simulation, method: str) -> None:
    """Takes the extremes of J over ``sim``'s fluid particles inside the water now (:func:`interior_mask`), kept
    apart per method and density estimate."""
    inside = interior_mask(sim)
    if inside.any():
        j = sim.particle_fields()["J"][inside]
        seen = _SEEN.setdefault((method, _density_estimates(sim)), _Extremes())
        seen.low, seen.high = min(seen.low, float(j.min())), max(seen.high, float(j.max()))


def records(case: str) -> list[Record]:
    """The extremes seen since :func:`reset` as ``case``'s records (resolution 0: over every simulation the case
    ran): judged against [:data:`LOW`, :data:`HIGH`] for the runs with the default density, reported for the
    variants a case runs beside it (as ``<case>_<density>``); none where no fluid particle was inside the water."""
    out = []
    for (method, estimate), seen in _SEEN.items():
        judged = estimate == DEFAULT_DENSITY
        name = case if judged else f"{case}_{estimate}"
        out.append(Record(name, method, 0.0, 0, "interior_fluid_J_min", seen.low, LOW if judged else None, ">="))
        out.append(Record(name, method, 0.0, 0, "interior_fluid_J_max", seen.high, HIGH if judged else None))
    return out


def interior_volume_ratios(sim: Simulation) -> np.ndarray:
    """J of the fluid particles inside the water (:func:`interior_mask`)."""
    return sim.particle_fields()["J"][interior_mask(sim)]


def interior_mask(sim: Simulation) -> np.ndarray:
    """Which particles are fluid at least :data:`DEPTH` cells inside the water: that far inside the walls, and no
    empty cell inside the walls within :data:`DEPTH` cells of the particle's own (along each axis and diagonally);
    none before the first step (J is not known yet)."""
    inside = np.zeros(sim.num_particles, dtype=bool)
    if sim.steps_done == 0:
        return inside
    fluid_bodies = [k for k, body in enumerate(sim.scene.bodies) if body.material.type == "fluid"]
    fluid = np.isin(sim.body, fluid_bodies)
    if not fluid.any():
        return inside
    h = sim.cell_size
    x = sim.positions
    deep = sim.wall_distance(x[fluid]) <= -DEPTH * h
    # Cells on a box around the particles, padded so that shifting by DEPTH never wraps onto one.
    cells = np.floor(x / h).astype(np.int64)
    pad = DEPTH + 1
    lo = cells.min(axis=0) - pad
    shape = tuple(cells.max(axis=0) - lo + pad + 1)
    occupied = np.zeros(shape, dtype=bool)
    occupied[tuple((cells - lo).T)] = True
    empty = np.argwhere(~occupied)
    air = np.zeros(shape, dtype=bool)
    if len(empty):
        centres = (empty + lo + 0.5) * h
        air[tuple(empty[sim.wall_distance(centres) < 0].T)] = True
    near_air = np.zeros(shape, dtype=bool)
    for offset in itertools.product(range(-DEPTH, DEPTH + 1), repeat=x.shape[1]):
        near_air |= np.roll(air, offset, axis=tuple(range(x.shape[1])))
    inside[np.flatnonzero(fluid)] = deep & ~near_air[tuple((cells[fluid] - lo).T)]
    return inside


def shipped(
    name: str, method: str = "augmented", density_estimate: str | None = None, outputs: int | None = None
) -> tuple[float, float, int] | None:
    """Runs the shipped scene ``name`` to its end (or its first ``outputs`` output steps) with ``method`` (its
    fluids' ``density_estimate`` replaced where one is given), watching the fluids' J inside the water at every
    output step: ``(lowest, highest, outputs)``, or None where no fluid particle was ever inside."""
    from augmpm.scene import load_scene

    scene = load_scene(name)
    if density_estimate is not None:
        fluids = [k for k, body in enumerate(scene.bodies) if body.material.type == "fluid"]
        scene = load_scene(name, values={f"bodies[{k}].material.density_estimate": density_estimate for k in fluids})
    sim = Simulation(scene, method)
    reset()
    done = 0
    while (outputs is None or done < outputs) and (
        (scene.time.steps is not None and sim.steps_done < scene.time.steps)
        or (scene.time.end is not None and sim.time < scene.time.end - 1e-12)
    ):
        left = scene.time.steps - sim.steps_done if scene.time.steps is not None else scene.time.output_interval
        sim.step(max(1, min(scene.time.output_interval, left)))
        watch(sim, method)
        done += 1
    seen = [extremes for (run, _), extremes in _SEEN.items() if run == method]
    return (min(e.low for e in seen), max(e.high for e in seen), done) if seen else None


def main(argv: list[str] | None = None) -> int:
    """Runs the shipped scenes with a fluid (the paper's scenes keep their own density and are left out) and
    prints the range of J inside the water; exits 1 when one leaves [LOW, HIGH]."""
    import argparse

    from augmpm._core import SimulationError
    from augmpm.scene import load_scene, shipped_scenes

    ap = argparse.ArgumentParser(prog="python -m augmpm.validation.bounds", description=main.__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", help="shipped scenes (default: every one with a fluid, the paper's left out)")
    ap.add_argument("--method", choices=("naive", "augmented"), default="augmented")
    ap.add_argument("--density-estimate", default=None, help="the fluids' density_estimate (default: the scene's)")
    ap.add_argument("--outputs", type=int, default=None, help="only the first N output steps (default: to the end)")
    args = ap.parse_args(argv)
    names = args.names or [
        name
        for name in shipped_scenes()
        if not name.startswith("paper") and any(b.material.type == "fluid" for b in load_scene(name).bodies)
    ]
    failed = False
    for name in names:
        try:
            result = shipped(name, args.method, args.density_estimate, args.outputs)
        except SimulationError as e:
            print(f"{name}: the run failed: {e}", flush=True)
            failed = True
            continue
        if result is None:
            print(f"{name}: no fluid particle {DEPTH} cells inside the water", flush=True)
            continue
        low, high, outputs = result
        ok = LOW <= low and high <= HIGH
        failed |= not ok
        print(f"{name}: J inside the water {low:.4f}–{high:.4f} over {outputs} outputs{'' if ok else '  NOT within'}",
              flush=True)  # fmt: skip
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
