"""The force each wall receives from the material (``metrics.csv``'s ``wall_force_<i>_x/_y``), and walls
posed from Python between steps (``Simulation.set_wall_pose``)."""

from __future__ import annotations

import csv
import shutil

import numpy as np
import pytest

import augmpm
from augmpm.run import METRIC_COLUMNS, resume_run, run_scene, wall_force_columns

G = 9.81


def _tank(**wall) -> augmpm.Scene:
    """Water (a disk, 53 kg per metre of depth) in a square slip container; ``wall`` adds keys to it."""
    scene = {
        "gravity": [0.0, -G],
        "grid": {"domain": [1.0, 1.0], "resolution": 40},
        "time": {"cfl": 0.5, "end": 3.2, "output_interval": 500},
        "wall_condition": "slip",
        "walls": [{"type": "polygon", "vertices": [[0.2, 0.15], [0.8, 0.15], [0.8, 0.75], [0.2, 0.75]], **wall}],
        "bodies": [
            {
                "shape": "circle",
                "center": [0.5, 0.33],
                "radius": 0.13,
                "material": {"type": "fluid", "density": 1000.0, "stiffness": 2e4, "viscosity": 2.0},
            }
        ],
    }
    return augmpm.Scene.from_dict(scene)


@pytest.mark.parametrize("method", ["naive", "augmented"])
def test_settled_water_weighs_on_the_floor_of_its_tank(method, tmp_path):
    """Water at rest in a tank (3.2 s, settled) pushes on its container with its weight M g: in the last
    interval of metrics.csv the container's force is (0, −M g) within 1% of M g, and the domain box,
    which the water never reaches, gets none."""
    result = run_scene(_tank(), tmp_path / "run", method, progress=False, render=False, animation=None)
    with open(result.out / "metrics.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == METRIC_COLUMNS + wall_force_columns(1)
    assert float(rows[0]["wall_force_0_y"]) == 0.0  # no interval before the first row
    weight = augmpm.Simulation(_tank(), method).masses.sum() * G
    last = rows[-1]
    assert abs(float(last["wall_force_0_y"]) + weight) < 0.01 * weight
    assert abs(float(last["wall_force_0_x"])) < 0.01 * weight
    assert float(last["wall_force_box_x"]) == float(last["wall_force_box_y"]) == 0.0


def test_wall_forces_resume_bitwise(tmp_path):
    """The forces of a resumed run are those of the uninterrupted one, byte for byte: a copy of a finished
    run resumed from its checkpoint at frame 4 computes frames 5 and 6 again and writes the same rows."""
    scene = _tank().model_copy(update={"time": _tank().time.model_copy(update={"end": 0.3, "output_interval": 50})})
    whole = run_scene(scene, tmp_path / "whole", progress=False, render=False, animation=None, checkpoint_every=4)
    assert whole.frames == 7
    shutil.copytree(tmp_path / "whole", tmp_path / "again")
    resume_run(tmp_path / "again", progress=False)
    assert (tmp_path / "again" / "metrics.csv").read_bytes() == (tmp_path / "whole" / "metrics.csv").read_bytes()


def test_a_posed_wall_carries_the_water_and_stays_in_the_checkpoint():
    """A container moved from Python each step (a sideways sway from where it stands, set as a pose and a
    velocity) carries the
    water with it, none of it outside (augmented), and its pose is part of the checkpoint: a simulation
    restored from it continues bitwise identically."""
    sim = augmpm.Simulation(_tank(), "augmented")
    sim.step(200)
    x0 = np.average(sim.positions[:, 0], weights=sim.masses)
    t0 = sim.time
    for k in range(300):
        t = sim.time - t0
        offset, speed = 0.02 * np.sin(4.0 * t), 0.08 * np.cos(4.0 * t)
        sim.set_wall_pose(0, (offset, 0.0), velocity=(speed, 0.0))
        sim.step(1)
        assert sim.metrics()["n_outside"] == 0, f"step {k}"
    state = sim.checkpoint()
    assert state["wall_pose"].shape == (1, 8) and state["wall_pose"][0, 0] == 0
    sim.step(50)
    again = augmpm.Simulation(_tank(), "augmented")
    again.restore(state)
    again.step(50)
    assert np.array_equal(again.positions, sim.positions)
    # The water went along with the walls (a fraction of the 2 cm sway), not nowhere.
    assert abs(np.average(sim.positions[:, 0], weights=sim.masses) - x0) > 1e-4


def test_a_checkpoint_without_the_walls_state_still_restores():
    """A checkpoint written before the walls' impulses and poses were kept restores, counting the impulse
    from there on."""
    sim = augmpm.Simulation(_tank(), "naive")
    sim.step(400)
    state = sim.checkpoint()
    at_checkpoint = state.pop("wall_impulse")
    del state["wall_pose"]
    again = augmpm.Simulation(_tank(), "naive")
    again.restore(state)
    again.step(20)
    sim.step(20)
    assert np.array_equal(again.positions, sim.positions)
    since = sim.wall_impulse - at_checkpoint
    assert np.abs(since).max() > 0
    assert np.allclose(again.wall_impulse, since, rtol=1e-9, atol=1e-9 * np.abs(sim.wall_impulse).max())


@pytest.mark.parametrize(
    ("args", "key"),
    [
        ((3, (0.0, 0.0)), "wall"),
        ((-1, (0.0, 0.0)), "wall"),
        ((0, (0.0,)), "position"),
        ((0, (0.5, 0.0)), "position"),
        ((0, (0.0, 0.0), float("nan")), "angle"),
        ((0, (0.0, 0.0), 0.0, (1e4, 0.0)), "velocity"),
        ((0, (0.0, 0.0), 0.0, (0.0, 0.0), "fast"), "angular_velocity"),
    ],
)
def test_bad_poses_are_refused_naming_the_argument(args, key):
    """A bad pose raises SceneError naming the argument and changes nothing."""
    sim = augmpm.Simulation(_tank(), "augmented")
    before = sim.checkpoint()
    with pytest.raises(augmpm.SceneError) as e:
        sim.set_wall_pose(*args)
    assert e.value.key == key
    after = sim.checkpoint()
    assert all(np.array_equal(before[k], after[k]) for k in before)


def test_the_paper_transfer_cannot_follow_a_posed_wall():
    """The paper's transfer holds particles against still walls only: posing a wall is refused."""
    scene = _tank().model_copy(update={"augmented": _tank().augmented.model_copy(update={"transfer": "paper"})})
    sim = augmpm.Simulation(scene, "augmented")
    with pytest.raises(augmpm.SceneError, match="stable"):
        sim.set_wall_pose(0, (0.0, 0.0), velocity=(0.1, 0.0))
