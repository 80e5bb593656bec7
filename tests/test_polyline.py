"""Open polylines as walls (`type = "polyline"`): a plate or a ramp of a given thickness with material all
around it; the augmented grid keeps material out of it on both sides; bad polylines are refused naming the
key."""

from __future__ import annotations

import numpy as np
import pytest

import augmpm


def _ramp(**ramp) -> dict:
    """Water dropped onto a ramp (a polyline 20° to the grid, 3.2 cells thick) in a box of 40 cells."""
    return {
        "gravity": [0.0, -9.81],
        "grid": {"domain": [1.0, 1.0], "resolution": 40},
        "time": {"cfl": 0.4, "end": 0.8, "output_interval": 20},
        "wall_condition": "slip",
        "walls": [
            {"type": "polygon", "vertices": [[0.03, 0.03], [0.97, 0.03], [0.97, 0.97], [0.03, 0.97]]},
            {"type": "polyline", "vertices": [[0.25, 0.55], [0.75, 0.368]], "thickness": 0.08, **ramp},
        ],
        "bodies": [
            {
                "shape": "box",
                "min": [0.3, 0.68],
                "max": [0.5, 0.8],
                "material": {"type": "fluid", "density": 1000.0, "stiffness": 3e4, "viscosity": 0.1},
            }
        ],
    }


def test_water_runs_off_a_ramp_and_around_it():
    """Water dropped on a ramp slides down it and falls off its lower end (0.8 s): with the augmented grid no
    particle is ever inside the ramp (checked every 20 steps), and water ends up below it as well as on it:
    the material lies on both sides of an open wall."""
    sim = augmpm.Simulation(augmpm.Scene.from_dict(_ramp()), "augmented", threads=2)
    total = round(0.8 / sim.dt)
    while sim.steps_done < total:
        sim.step(20)
        assert sim.metrics()["n_outside"] == 0, f"step {sim.steps_done}"
    x = sim.positions
    # Height of the ramp's centreline at each particle's x (it runs from (0.25, 0.55) to (0.75, 0.368)).
    centre = 0.55 + (x[:, 0] - 0.25) * (0.368 - 0.55) / 0.5
    below = (x[:, 1] < centre) & (x[:, 0] > 0.25) & (x[:, 0] < 0.75)
    assert below.sum() > 0.2 * len(x), f"{below.sum()} of {len(x)} below the ramp"
    assert (x[:, 1] > centre + 0.04).any()


def test_the_naive_walls_let_water_into_the_ramp():
    """The same drop with the naive walls runs, and particles end up inside the ramp: the grid nodes it
    classifies cannot hold material off a wall at an angle to the grid (the paper's point)."""
    sim = augmpm.Simulation(augmpm.Scene.from_dict(_ramp()), "naive", threads=2)
    most = 0
    while sim.steps_done < round(0.8 / sim.dt):
        sim.step(20)
        most = max(most, sim.metrics()["n_outside"])
    assert most > 0


def test_a_polyline_outline_is_its_stroke():
    """A polyline is drawn as its outline: every outline point lies half the thickness from the centreline."""
    sim = augmpm.Simulation(augmpm.Scene.from_dict(_ramp()), "naive")
    outline, moving = sim.wall_outlines()[1]
    a, b = np.array([0.25, 0.55]), np.array([0.75, 0.368])
    t = np.clip((outline - a) @ (b - a) / ((b - a) @ (b - a)), 0.0, 1.0)
    distance = np.linalg.norm(outline - (a + t[:, None] * (b - a)), axis=1)
    assert not moving and np.allclose(distance, 0.04, atol=1e-12)
    assert np.allclose(sim.wall_distance(outline), 0.0, atol=1e-12)


@pytest.mark.parametrize(
    ("ramp", "key", "reason"),
    [
        ({"vertices": [[0.3, 0.5], [0.3, 0.5], [0.6, 0.4]]}, "walls[1].vertices", "coincide"),
        ({"vertices": [[0.3, 0.5]]}, "walls[1].vertices", ""),
        ({"thickness": 0.0}, "walls[1].thickness", ""),
        ({"side": "inside"}, "walls[1]", "side"),
    ],
)
def test_bad_polylines_are_refused_naming_the_key(ramp, key, reason):
    """A polyline with coinciding points, one point, no thickness or a side raises SceneError naming the key."""
    with pytest.raises(augmpm.SceneError) as e:
        augmpm.Simulation(augmpm.Scene.from_dict(_ramp(**ramp)), "augmented")
    assert e.value.key.startswith(key) and reason in str(e.value)
