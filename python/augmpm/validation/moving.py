"""Case: walls that move. Water in containers (a square tilted 20° to the grid, and a circle) that are
carried, turned and shaken, and water pushed along a channel by a piston: with the augmented grid no particle
gets past a wall at any sampled step (nor behind the piston), and none is deeper than 0.05 h."""

from __future__ import annotations

import numpy as np

from augmpm._core import SimulationError
from augmpm.scene import Scene
from augmpm.simulation import Simulation
from augmpm.validation import bounds
from augmpm.validation.common import METHODS, CaseFailed, fluid, simulate
from augmpm.validation.records import Record

G = 9.81
#: The tilted square container (m), counter-clockwise, and the water inside it.
SQUARE = [[0.35, 0.2], [0.7064, 0.3297], [0.5767, 0.6861], [0.2203, 0.5564]]
SQUARE_WATER = [[0.36, 0.23], [0.69, 0.35], [0.64, 0.49], [0.31, 0.37]]
CIRCLE = ([0.5, 0.45], 0.22)
CIRCLE_WATER = ([0.5, 0.36], 0.11)
MOTIONS = {
    # Carried there and back at 0.1 m/s (a keyframed path that stays in the domain however long the run).
    "carried": {
        "type": "keyframes",
        "times": [0.0, 1.5, 3.0, 4.5, 6.0, 7.5, 9.0],
        "positions": [[0.0, 0.0], [0.134, 0.067], [0.0, 0.0], [-0.134, -0.067], [0.0, 0.0], [0.134, 0.067], [0.0, 0.0]],
    },
    "turned": {"type": "constant", "angular_velocity": 0.8},
    "shaken": {"type": "oscillation", "amplitude": [0.03, 0.015], "angular_amplitude": 0.1, "frequency": 1.5},
}


def _container(shape: str, motion: dict, resolution: int, steps_hint: int) -> dict:
    water = fluid(1000.0, 8.0, 0.1)
    if shape == "square":
        wall = {"type": "polygon", "vertices": SQUARE, "motion": motion}
        body = {"shape": "polygon", "vertices": SQUARE_WATER, "material": water}
    else:
        (c, r), (wc, wr) = CIRCLE, CIRCLE_WATER
        wall = {"type": "circle", "center": c, "radius": r, "side": "inside", "motion": motion}
        body = {"shape": "circle", "center": wc, "radius": wr, "material": water}
    return {
        "name": f"moving_{shape}",
        "seed": 9,
        "gravity": [0.0, -G],
        "grid": {"domain": [1.0, 1.0], "resolution": resolution},
        "time": {"cfl": 0.4, "steps": steps_hint, "output_interval": 1},
        "wall_condition": "slip",
        "walls": [wall],
        "bodies": [body],
    }


def _piston(resolution: int) -> tuple[dict, float, float]:
    """Water ahead of a plate pushed 0.35 m along a channel in 1.2 s; the plate's back face at x = 0.06 m
    and its speed (m/s)."""
    scene = {
        "name": "moving_piston",
        "seed": 4,
        "gravity": [0.0, -G],
        "grid": {"domain": [1.0, 1.0], "resolution": resolution},
        "time": {"cfl": 0.4, "steps": 1, "output_interval": 1},
        "wall_condition": "slip",
        "walls": [
            {"type": "polygon", "vertices": [[0.02, 0.05], [0.98, 0.134], [0.98, 0.97], [0.02, 0.97]]},
            {
                "type": "polygon",
                "side": "outside",
                "vertices": [[0.06, 0.0], [0.1, 0.0], [0.1, 1.0], [0.06, 1.0]],
                "motion": {"type": "keyframes", "times": [0.0, 1.2], "positions": [[0.0, 0.0], [0.35, 0.0]]},
            },
        ],
        "bodies": [
            {
                "shape": "polygon",
                "vertices": [[0.11, 0.065], [0.45, 0.095], [0.45, 0.35], [0.11, 0.35]],
                "material": fluid(1000.0, 8.0, 0.1),
            }
        ],
    }
    return scene, 0.06, 0.35 / 1.2


def _every(scene: dict, method: str, steps: int, samples: int) -> list[dict]:
    """The metrics after every `steps / samples` steps of `steps`; raises CaseFailed."""
    sim = Simulation(Scene.from_dict(scene), method)
    out = []
    for _ in range(samples):
        try:
            sim.step(steps // samples)
        except SimulationError as e:
            raise CaseFailed(str(e), sim.time) from None
        out.append(sim.metrics())
        bounds.watch(sim, method)
    return out


def run(quick: bool) -> tuple[list[Record], dict]:
    """Each container shape and motion, and the piston, for 2,000 steps (quick) or 10,000 (full)."""
    resolution = 64
    steps = 2000 if quick else 10000
    records: list[Record] = []
    data: dict = {}
    cases = [(shape, name) for shape in ("square", "circle") for name in MOTIONS]
    for shape, name in cases:
        case = f"moving_{shape}_{name}"
        scene = _container(shape, MOTIONS[name], resolution, steps)
        for method in METHODS:
            try:
                sampled = _every(scene, method, steps, 50)
            except CaseFailed as e:
                records.append(Record.failed_run(case, method, 20.0, resolution, e))
                continue
            outside = max(m["n_outside"] for m in sampled)
            deepest = max(m["max_penetration"] for m in sampled)
            tol = (0.0, 0.05) if method == "augmented" else (None, None)
            records.append(Record(case, method, 20.0, resolution, "particles_outside_max", outside, tol[0]))
            records.append(Record(case, method, 20.0, resolution, "deepest_h", deepest, tol[1]))
            data[(case, method)] = (outside, deepest)
    scene, back, speed = _piston(resolution)
    for method in METHODS:
        times = list(np.linspace(0.05, 2.0, 40))

        def behind(sim):
            # The plate's back face at time t; a particle at a smaller x is behind the piston.
            face = back + speed * min(sim.time, 1.2)
            return int((sim.positions[:, 0] < face).sum()), sim.metrics()["n_outside"]

        try:
            sampled, _ = simulate(scene, method, times, behind)
        except CaseFailed as e:
            records.append(Record.failed_run("moving_piston", method, 5.0, resolution, e))
            continue
        tol = 0.0 if method == "augmented" else None
        most_behind, most_outside = max(b for b, _ in sampled), max(o for _, o in sampled)
        records.append(Record("moving_piston", method, 5.0, resolution, "particles_behind_max", most_behind, tol))
        records.append(Record("moving_piston", method, 5.0, resolution, "particles_outside_max", most_outside, tol))
    return records, data
