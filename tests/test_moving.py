"""Walls that move as rigid bodies (`walls[i].motion`): the material stays inside them with the augmented grid,
runs resume bitwise, frames draw each wall where it is, and bad motions are refused naming the key."""

from __future__ import annotations

import numpy as np
import pytest

import augmpm
from augmpm.render import FrameRenderer

MOVING = [
    "moving/shaken_tank",
    "moving/turning_box",
    "moving/keyframed_tank",
    "moving/stirred_tank",
    "moving/piston",
    "moving/plate_in_snow",
]


@pytest.mark.parametrize("name", MOVING)
def test_moving_scenes_keep_the_material_inside_with_the_augmented_grid(name):
    """Each shipped moving scene, 600 steps (0.2 s) with both methods: the augmented grid keeps every particle
    inside the walls at every 50th step; the naive walls run too (they leak: `augmpm compare` shows it)."""
    scene = augmpm.load_scene(name)
    for method in ("naive", "augmented"):
        sim = augmpm.Simulation(scene, method, threads=2)
        for _ in range(12):
            sim.step(50)
            if method == "augmented":
                assert sim.metrics()["n_outside"] == 0, f"{name}: step {sim.steps_done}"


def test_a_run_with_moving_walls_resumes_bitwise():
    """A checkpoint of a run whose walls move restores into a fresh simulation that continues it bit for bit:
    the walls' pose follows from the time, which the checkpoint holds."""
    scene = augmpm.load_scene("moving/turning_box")
    whole = augmpm.Simulation(scene, "augmented", threads=2)
    whole.step(150)
    saved = whole.checkpoint()
    whole.step(150)
    resumed = augmpm.Simulation(scene, "augmented", threads=1)
    resumed.restore(saved)
    resumed.step(150)
    assert np.array_equal(resumed.positions, whole.positions)
    assert np.array_equal(resumed.velocities, whole.velocities)
    outline = next(o for o, moving in resumed.wall_outlines() if moving)
    assert np.array_equal(outline, next(o for o, moving in whole.wall_outlines() if moving))


def test_a_turning_wall_is_where_its_motion_puts_it():
    """The box of `turning_box` turns at π/2 rad/s about its centre (0.5, 0.5): after 0.5 s its first corner,
    drawn 0.25√2 m from the centre at 225°, is at 270°: (0.5, 0.5 − 0.25√2)."""
    scene = augmpm.load_scene("moving/turning_box")
    sim = augmpm.Simulation(scene, "naive")
    sim.step(round(0.5 / sim.dt))
    ((outline, moving),) = sim.wall_outlines()
    angle = 1.5708 * sim.time
    r = 0.25 * np.sqrt(2)
    expected = [0.5 + r * np.cos(np.radians(225) + angle), 0.5 + r * np.sin(np.radians(225) + angle)]
    assert moving and np.allclose(outline[0], expected, atol=1e-12)


def test_frames_draw_each_moving_wall_where_it_is(tmp_path):
    """A frame draws a moving wall's outline at its pose then: frames at two times differ along the wall, and
    the background (drawn once) does not hold it."""
    scene = augmpm.load_scene("moving/shaken_tank")
    sim = augmpm.Simulation(scene, "naive")
    renderer = FrameRenderer(scene)
    empty = np.zeros((0, 2)), np.zeros(0, dtype=int)
    frames = []
    for t in (0.0, 1 / 6):  # a quarter period: 4 cm to the right
        sim.step(round(t / sim.dt) - sim.steps_done)
        walls = [o for o, moving in sim.wall_outlines() if moving]
        frames.append(renderer._compose(*empty, sim.time, walls)[0])
    renderer.close()
    assert not np.array_equal(frames[0], frames[1])
    dark = (frames[0] < 100).all(axis=2)
    assert dark.sum() > 500 and not (renderer.background[dark] < 100).all()


@pytest.mark.parametrize(
    ("motion", "key", "reason"),
    [
        ({"type": "oscillation", "amplitude": [0.1, 0.0]}, "walls[0].motion.frequency", "required key is missing"),
        (
            {"type": "keyframes", "times": [0.0, 1.0], "positions": [[0.0, 0.0]]},
            "walls[0].motion.positions",
            "1 positions for 2 times",
        ),
        (
            {"type": "keyframes", "times": [1.0, 0.5], "positions": [[0, 0], [0, 0]]},
            "walls[0].motion.times",
            "must increase",
        ),
        ({"type": "constant", "velocty": [1.0, 0.0]}, "walls[0].motion.velocty", "did you mean 'velocity'"),
        ({"type": "constant", "velocity": [500.0, 0.0]}, "walls[0].motion", "cells in a step"),
    ],
)
def test_bad_motions_are_refused_naming_the_key(small_scene, motion, key, reason):
    small_scene["walls"][0]["motion"] = motion
    small_scene["time"] = {"dt": 1e-3, "steps": 1, "output_interval": 1}
    with pytest.raises(augmpm.SceneError) as err:
        augmpm.Simulation(augmpm.Scene.from_dict(small_scene))
    assert err.value.key == key and reason in err.value.reason, str(err.value)


def test_the_vtk_series_carries_the_walls_of_each_frame(tmp_path):
    """`augmpm run` of a scene whose walls move writes each frame's walls (vtk/walls/frame_*.vtp, indexed by
    walls.pvd beside particles.pvd): one per frame, each where the walls were then. Still walls are written
    once (vtk/walls/walls.vtp)."""
    from augmpm.cli import main

    out = tmp_path / "turning"
    args = ["run", "moving/turning_box", "--out", str(out), "--set", "time.end=0.05", "--no-render", "--no-progress"]
    assert main(args) == 0
    frames = sorted((out / "vtk" / "walls").glob("frame_*.vtp"))
    assert len(frames) == len(list((out / "vtk").glob("frame_*.vtp"))) >= 3
    assert frames[0].read_text() != frames[-1].read_text()
    assert (out / "walls.pvd").read_text().count("vtk/walls/frame_") == len(frames)
    still = tmp_path / "still"
    args = ["run", "dam_break", "--out", str(still), "--steps", "40", "--no-render", "--no-progress"]
    assert main(args) == 0
    assert (still / "vtk" / "walls" / "walls.vtp").exists() and not (still / "walls.pvd").exists()


def test_the_papers_transfer_is_refused_with_moving_walls(small_scene):
    """The paper's transfer holds particles found past a wall against a still wall; with a moving wall it is
    refused naming the key, not run wrong."""
    small_scene["walls"][0]["motion"] = {"type": "constant", "velocity": [0.01, 0.0]}
    small_scene["augmented"] = {"transfer": "paper"}
    with pytest.raises(augmpm.SceneError) as err:
        augmpm.Simulation(augmpm.Scene.from_dict(small_scene), "augmented")
    assert err.value.key == "augmented.transfer"
    augmpm.Simulation(augmpm.Scene.from_dict(small_scene), "naive")


def test_a_shaken_3d_tank_keeps_its_water_and_resumes_bitwise(tmp_path):
    """scenes/moving/shaken_tank_3d (a box tank turned about an axis in no coordinate plane, shaken along x
    and z and rocked about z; 24 cells), 0.25 s: the augmented grid keeps every particle inside at every 30th
    step while the naive walls let some through; a checkpoint restores on one thread into a run that continues
    the two-thread one bit for bit; frames draw the tank's surface points where it is (two frames a quarter
    period apart differ where only the walls are drawn)."""
    scene = augmpm.load_scene("moving/shaken_tank_3d")
    most = {}
    for method in ("naive", "augmented"):
        sim = augmpm.Simulation(scene, method, threads=2)
        most[method] = 0
        for _ in range(10):
            sim.step(30)
            most[method] = max(most[method], sim.metrics()["n_outside"])
    assert most["augmented"] == 0 and most["naive"] > 0, most
    saved = sim.checkpoint()
    sim.step(40)
    resumed = augmpm.Simulation(scene, "augmented", threads=1)
    resumed.restore(saved)
    resumed.step(40)
    assert np.array_equal(resumed.positions, sim.positions) and np.array_equal(resumed.velocities, sim.velocities)
    renderer = FrameRenderer(scene)
    empty = np.zeros((0, 3)), np.zeros(0, dtype=int)
    frames = []
    naive = augmpm.Simulation(scene, "naive")
    for t in (0.0, 1 / 6):  # a quarter period: 5 cm along x, 2 along z, rocked 0.15 rad
        naive.step(round(t / naive.dt) - naive.steps_done)
        frames.append(renderer._compose(*empty, naive.time, [naive.wall_points(0.5 * naive.cell_size)])[0])
    renderer.close()
    assert (np.abs(frames[0].astype(int) - frames[1]).sum(axis=2) > 0).sum() > 500


def test_bad_3d_motions_are_refused_naming_the_key():
    """A 3D wall's motion is checked as in 2D: keyframes need a position per time, in increasing time; a
    wall may not move more than a cell per step of a given dt."""
    base = augmpm.load_scene("moving/shaken_tank_3d").to_dict()
    cases = [
        ({"type": "keyframes", "times": [0.0, 1.0], "positions": [[0.0, 0.0, 0.0]]}, "walls[0].motion.positions"),
        (
            {"type": "keyframes", "times": [0.0, 1.0], "positions": [[0.0] * 3] * 2, "rotations": [[0.0] * 3]},
            "walls[0].motion.rotations",
        ),
        ({"type": "constant", "velocity": [50.0, 0.0, 0.0]}, "walls[0].motion"),
    ]
    for motion, key in cases:
        data = {**base, "walls": [{**base["walls"][0], "motion": motion}], "time": {**base["time"], "dt": 1e-3}}
        data["time"].pop("cfl")
        with pytest.raises(augmpm.SceneError) as e:
            augmpm.Simulation(augmpm.Scene3.from_dict(data))
        assert e.value.key == key, (e.value.key, e.value.reason)


def test_a_moving_3d_wall_is_written_to_the_vtk_series_in_each_frame(tmp_path):
    """A 3D run whose tank moves writes the tank's surface points in every frame (vtk/walls/, listed in
    walls.pvd): the first and the last frame's points differ, by the tank's shake."""
    from augmpm.run import run_scene

    scene = augmpm.load_scene("moving/shaken_tank_3d")
    result = run_scene(scene, tmp_path / "run", steps=60, progress=False, render=False)
    pvd = (result.out / "walls.pvd").read_text()
    files = sorted((result.out / "vtk" / "walls").glob("frame_*.vtp"))
    assert len(files) == 4 and all(f.name in pvd for f in files)
    assert files[0].read_text() != files[-1].read_text()
