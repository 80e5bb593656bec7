"""Sand (`type = "sand"`, Drucker–Prager after Klár et al. 2016) in whole runs: cohesion holds a vertical cut up
to its critical height, and a 3D column collapses and comes to rest inside tilted walls. The return mapping
itself is tested in the core (`material/sand_klar2016.rs`); the run-out and the heap's angle in
`augmpm validate` (tests/test_validation.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import augmpm
from augmpm.validation.common import Frame, simulate

RHO, G, PHI = 2200.0, 9.81, 30.0


def _cut(cohesion: float) -> tuple[dict, Frame]:
    """A free-standing block of sand 0.1 m wide and 0.1 m high on a sticky floor turned 20° to the grid."""
    frame = Frame((0.3, 0.1), 20.0)
    g = -G * frame.n
    material = {"type": "sand", "density": RHO, "youngs_modulus": 3.537e5, "poisson_ratio": 0.3,
                "friction_angle": PHI, "cohesion": cohesion}  # fmt: skip
    return {
        "gravity": [float(g[0]), float(g[1])],
        "grid": {"domain": [1.0, 1.0], "resolution": 160},
        "time": {"cfl": 0.5, "steps": 1, "output_interval": 1},
        "wall_condition": "sticky",
        "walls": [{"type": "polygon", "vertices": frame.rect(-0.2, 0.3, 0.0, 0.4)}],
        "bodies": [{"shape": "polygon", "vertices": frame.rect(0.0, 0.1, 1e-6, 0.1), "material": material}],
    }, frame


@pytest.mark.parametrize(("factor", "stands"), [(2.0, True), (0.5, False)])
def test_cohesion_holds_a_vertical_cut_up_to_its_critical_height(factor, stands):
    """A vertical cut in a Mohr–Coulomb material stands up to H_c ≈ 3.8 (c/ρg) tan(45° + φ/2) (the limit
    analysis bounds are 3.64 and 3.83). A 0.1 m block whose cohesion makes H_c twice its height keeps its
    top (it sinks by less than 5% of its height in 0.4 s: 0.5% measured, of which elastic settling under
    its own weight, ρgH/2E, is 0.3%), and one whose H_c is half its height slumps (its top falls by more
    than 20%: 34% measured). Walls at 20° to the grid, augmented."""
    cohesion = factor * 0.1 * RHO * G / (3.8 * math.tan(math.radians(45.0 + PHI / 2)))
    scene, frame = _cut(cohesion)
    (top,), sim = simulate(scene, "augmented", [0.4], lambda sim: float(np.max(frame.coords(sim.positions)[1])))
    drop = (0.1 - top) / 0.1
    assert (drop < 0.05) if stands else (drop > 0.2), drop
    assert sim.metrics()["n_outside"] == 0


def test_a_3d_sand_column_spreads_and_comes_to_rest_inside_a_turned_box():
    """In 3D (the cone through Mohr–Coulomb's compression corners), a cylinder of cohesionless sand as high as
    it is wide, in a box turned 0.4 rad about (1, 2, 0.5) (its floor tilted ~11°) with separate walls of
    friction μ = tan 30° and gravity along −y, spreads (its footprint's radius grows by more than a quarter:
    2.7× measured, at 20 cells) and comes to rest (largest speed under 0.05 m/s after 0.8 s: 0.013 measured,
    against a free-fall speed √(2gH) = 2.0 m/s), with no particle outside the box."""
    material = {"type": "sand", "density": RHO, "youngs_modulus": 3.537e5, "poisson_ratio": 0.3, "friction_angle": PHI}
    scene = augmpm.Scene3.from_dict(
        {
            "gravity": [0.0, -G, 0.0],
            "grid": {"domain": [1.0, 1.0, 1.0], "resolution": 20},
            "time": {"cfl": 0.5, "steps": 1, "output_interval": 1},
            "wall_condition": "separate",
            "wall_friction": 0.577,
            "walls": [
                {"type": "box", "center": [0.5, 0.5, 0.5], "size": [0.8, 0.8, 0.8], "axis": [1, 2, 0.5], "angle": 0.4}
            ],
            "bodies": [
                {
                    "shape": "cylinder",
                    "center": [0.5, 0.26, 0.5],
                    "axis": [0.0, 1.0, 0.0],
                    "radius": 0.1,
                    "length": 0.2,
                    "material": material,
                }
            ],
        }
    )
    sim = augmpm.Simulation(scene, "augmented")
    radius = lambda x: float(np.percentile(np.hypot(x[:, 0] - 0.5, x[:, 2] - 0.5), 95))  # noqa: E731
    r0 = radius(sim.positions)
    sim.step(max(1, round(0.8 / sim.dt)))
    assert radius(sim.positions) > 1.25 * r0
    assert float(np.linalg.norm(sim.velocities, axis=1).max()) < 0.05
    assert sim.metrics()["n_outside"] == 0


def test_sand_runs_bitwise_the_same_on_one_thread_and_two():
    """Determinism: the sand column of `augmpm validate` at 48 cells across (9,216 particles, enough for the
    step to split across threads; walls at 30°, 150 steps) reaches bitwise the same state on one thread as on
    two, with either wall method."""
    from augmpm.validation import granular

    scene = augmpm.Scene.from_dict(granular.column_scene(1.0, 48, 30.0)[0])
    for method in ("naive", "augmented"):
        states = []
        for threads in (1, 2):
            sim = augmpm.Simulation(scene, method, threads=threads)
            sim.step(150)
            states.append(sim.checkpoint())
        for key in ("x", "v", "c", "f", "jp"):
            assert np.array_equal(states[0][key], states[1][key]), (method, key)
