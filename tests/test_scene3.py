"""3D scenes (``grid.domain`` with three components): the same keys with three-component vectors and 3D
walls and bodies, run from Python and ``augmpm run`` with (N, 3) arrays, checkpoints that resume bitwise,
and the paper's comparison in 3D (``scenes/paper3d/``)."""

from __future__ import annotations

import csv
import shutil

import imageio.v3 as iio
import numpy as np
import pytest

import augmpm
from augmpm.run import METRIC_COLUMNS, resume_run, run_scene, wall_force_columns


def _tank(**keys) -> dict:
    return {
        "gravity": [0.0, -9.81, 0.0],
        "grid": {"domain": [1.0, 1.0, 1.0], "resolution": 16},
        "time": {"cfl": 0.4, "end": 0.3, "output_interval": 20},
        "wall_condition": "slip",
        "walls": [
            {"type": "box", "center": [0.5, 0.45, 0.5], "size": [0.6, 0.5, 0.6], "axis": [1, 2, 0.5], "angle": 0.4}
        ],
        "bodies": [
            {
                "shape": "sphere",
                "center": [0.5, 0.5, 0.5],
                "radius": 0.12,
                "material": {"type": "fluid", "density": 1000.0, "stiffness": 1e4, "viscosity": 1.0},
            }
        ],
        **keys,
    }


PAPER3D = ["fluid_incline_noslip", "fluid_incline_fullslip", "elastic_incline_fullslip", "snow_incline_fullslip"]
PAPER3D += ["fluid_sphere_noslip"]


@pytest.mark.parametrize("name", PAPER3D)
def test_the_paper_experiments_in_3d_leak_with_naive_walls_only(name):
    """Each scene of scenes/paper3d (Fig. 1 and 5 in 3D: fluid, elastic and snow bodies dropped into a
    container whose floor's normal lies in no coordinate plane, and fluid poured around a sphere; 32 cells,
    1 s): the augmented grid keeps 0 particles outside at every 40th step; the naive walls let particles
    through (15 to 2,557 at most when measured)."""
    scene = augmpm.load_scene(f"paper3d/{name}")
    assert isinstance(scene, augmpm.Scene3)
    outside = {}
    for method in ("naive", "augmented"):
        sim = augmpm.Simulation(scene, method, threads=2)
        total = scene.time.total_steps(sim.dt)
        most = 0
        while sim.steps_done < total:
            sim.step(min(40, total - sim.steps_done))
            most = max(most, sim.metrics()["n_outside"])
        outside[method] = (most, sim.metrics()["n_outside"])
    assert outside["augmented"] == (0, 0)
    assert outside["naive"][0] > 0


def test_a_3d_simulation_has_3d_arrays_and_resumes_bitwise():
    """Positions, velocities and boundary points are (N, 3); a checkpoint restores into a fresh simulation
    that continues bit for bit; posing a wall is refused (3D walls do not move yet)."""
    scene = augmpm.Scene3.from_dict(_tank())
    sim = augmpm.Simulation(scene, threads=2)
    assert sim.dim == 3 and sim.positions.shape == (sim.num_particles, 3)
    # The container's faces (1.92 m²) at spacing h: at least one point per h² of surface.
    assert sim.boundary_points.shape[1] == 3 and len(sim.boundary_points) >= 1.92 * 16**2
    sim.step(60)
    saved = sim.checkpoint()
    sim.step(60)
    again = augmpm.Simulation(scene, threads=1)
    again.restore(saved)
    again.step(60)
    assert np.array_equal(again.positions, sim.positions) and np.array_equal(again.velocities, sim.velocities)
    assert sim.wall_distance(np.array([[0.5, 0.45, 0.5]]))[0] < -0.2


def test_a_posed_3d_wall_carries_the_water_and_stays_in_the_checkpoint():
    """A 3D container swayed from Python each step (a pose and a velocity along x, a rock about z as a
    rotation vector) carries the water with it, none of it outside (augmented); its pose is part of the
    checkpoint (one row of the wall's index and 13 numbers), and a simulation restored from it continues
    bitwise identically. A pose with a wrong count of numbers, or of a plane, is refused naming the
    argument."""
    scene = augmpm.Scene3.from_dict(_tank())
    sim = augmpm.Simulation(scene, "augmented", threads=1)
    sim.step(20)
    x0 = np.average(sim.positions[:, 0], weights=sim.masses)
    t0 = sim.time
    for k in range(60):
        t = sim.time - t0
        offset, speed = 0.02 * np.sin(8.0 * t), 0.16 * np.cos(8.0 * t)
        sim.set_wall_pose(0, (offset, 0.0, 0.0), angle=(0.0, 0.0, offset), velocity=(speed, 0.0, 0.0),
                          angular_velocity=(0.0, 0.0, speed))  # fmt: skip
        sim.step(1)
        assert sim.metrics()["n_outside"] == 0, f"step {k}"
    state = sim.checkpoint()
    assert state["wall_pose"].shape == (1, 14) and state["wall_pose"][0, 0] == 0
    sim.step(20)
    again = augmpm.Simulation(scene, "augmented", threads=2)
    again.restore(state)
    again.step(20)
    assert np.array_equal(again.positions, sim.positions)
    assert abs(np.average(sim.positions[:, 0], weights=sim.masses) - x0) > 1e-4
    for args, key in [
        ((0, (0.0, 0.0)), "position"),
        ((0, (0.0, 0.0, 0.0), 0.1), "angle"),
        ((0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0)), "velocity"),
        ((1, (0.0, 0.0, 0.0)), "wall"),
    ]:
        with pytest.raises(augmpm.SceneError) as e:
            sim.set_wall_pose(*args)
        assert e.value.key == key
    plane = augmpm.Scene3.from_dict(_tank(walls=[{"type": "plane", "point": [0.5, 0.2, 0.5], "normal": [0, 1, 0]}]))
    with pytest.raises(augmpm.SceneError, match="plane, which cannot move") as e:
        augmpm.Simulation(plane, "augmented").set_wall_pose(0, (0.0, 0.0, 0.0))
    assert e.value.key == "wall"


def test_a_3d_run_writes_3d_outputs_and_resumes_bitwise(tmp_path):
    """``run_scene`` on a 3D scene writes (N, 3) particles, VTK points in 3D, x, y, z wall forces and frames
    seen from one side (the walls as grey points, the water in its body colour, shaded by depth); a copy
    resumed from its checkpoint at frame 4 writes the same metrics.csv and frames."""
    scene = augmpm.Scene3.from_dict(_tank())
    result = run_scene(scene, tmp_path / "run", progress=False, checkpoint_every=4, animation=None)
    with np.load(result.out / "particles" / "frame_00003.npz") as z:
        assert z["x"].shape[1] == 3 and z["v"].shape[1] == 3
    with open(result.out / "metrics.csv", newline="") as f:
        header = next(csv.reader(f))
    assert header == METRIC_COLUMNS + wall_force_columns(1, 3)
    assert 'NumberOfPoints="' in (result.out / "vtk" / "frame_00001.vtp").read_text()
    # The still container, once, as its surface points (at least one per h² of its 1.92 m² of faces).
    walls = (result.out / "vtk" / "walls" / "walls.vtp").read_text()
    assert int(walls.split('NumberOfPoints="')[1].split('"')[0]) > 1.92 * 16**2
    image = iio.imread(result.out / "frames" / "frame_00003.png")[..., :3].astype(int)
    blue = (image[..., 2] > image[..., 0] + 60) & (image[..., 2] > 90)  # tab10's first colour, shaded
    grey = (np.ptp(image, axis=2) < 8) & (image[..., 0] > 120) & (image[..., 0] < 230)
    assert blue.sum() > 500 and grey.sum() > 500, (blue.sum(), grey.sum())
    shutil.copytree(result.out, tmp_path / "again")
    resume_run(tmp_path / "again", progress=False)
    assert (tmp_path / "again" / "metrics.csv").read_bytes() == (result.out / "metrics.csv").read_bytes()
    for frame in sorted((result.out / "frames").glob("*.png")):
        assert (tmp_path / "again" / "frames" / frame.name).read_bytes() == frame.read_bytes()


@pytest.mark.parametrize(
    ("change", "key"),
    [
        (
            {"walls": [{"type": "box", "center": [0.5, 0.5, 0.5], "size": [0.5, 0.5, 0.5], "axs": [1, 0, 0]}]},
            "walls[0].axs",
        ),
        ({"walls": [{"type": "polygon", "vertices": [[0, 0], [1, 0], [1, 1]]}]}, "walls[0]"),
        ({"gravity": [0.0, -9.81]}, "gravity"),
        ({"walls": [{"type": "plane", "point": [0.5, 0.2, 0.5], "normal": [0, 0, 0]}]}, "walls[0].normal"),
        ({"grid": {"domain": [1.0, 1.01, 1.0], "resolution": 16}}, "grid.domain"),
    ],
)
def test_bad_3d_scenes_are_refused_naming_the_key(change, key):
    """A bad 3D scene raises SceneError naming the key (with a did-you-mean from the 3D keys)."""
    with pytest.raises(augmpm.SceneError) as e:
        augmpm.Simulation(augmpm.Scene3.from_dict(_tank(**change)))
    assert e.value.key.startswith(key)
    if key.endswith("axs"):
        assert "did you mean 'axis'" in str(e.value)


def test_3d_results_do_not_depend_on_the_thread_count():
    """A 3D run of 4,700 particles (above the size that stays on one thread) reaches bitwise the same
    state on one thread and on two."""
    water = _tank()["bodies"][0]["material"]
    body = {"shape": "box", "min": [0.35, 0.4, 0.35], "max": [0.65, 0.6, 0.65], "material": water}
    scene = augmpm.Scene3.from_dict(_tank(grid={"domain": [1.0, 1.0, 1.0], "resolution": 32}, bodies=[body]))
    runs = []
    for threads in (1, 2):
        sim = augmpm.Simulation(scene, threads=threads)
        assert sim.num_particles > 4096  # PARALLEL_MIN
        sim.step(40)
        runs.append((sim.positions, sim.velocities))
    assert np.array_equal(runs[0][0], runs[1][0]) and np.array_equal(runs[0][1], runs[1][1])


@pytest.mark.parametrize(("precision", "tol_v", "tol_c"), [("f64", 1e-13, 1e-11), ("f32", 2e-6, 3e-4)])
def test_a_rigid_motion_comes_back_from_the_grid_unchanged(precision, tol_v, tol_c):
    """APIC carries an affine velocity field exactly: water moving rigidly (v = v0 + ω × (x − x_c), C = [ω]×,
    stress-free at J = 1, no gravity, no walls) gets back from one step's P2G and G2P the same v at its
    positions before the step and the same C, to rounding: ~1e-16 m/s and 1e-14 1/s in f64, 1.5e-7 m/s and
    1.5e-5 1/s in f32, where each of G2P's 27 terms rounds to ε |v| and C is scaled by 4/h² (h = 1/32 m). In
    f32 this is the path of the SSE2 row sums on x86-64 (`step/rows_sse.rs`), whose unit test covers only the
    sums."""
    water = _tank()["bodies"][0]["material"]
    body = {"shape": "box", "min": [0.35, 0.35, 0.35], "max": [0.65, 0.65, 0.65], "material": water}
    grid = {"domain": [1.0, 1.0, 1.0], "resolution": 32}
    scene = augmpm.Scene3.from_dict(
        _tank(gravity=[0.0, 0.0, 0.0], walls=[], bodies=[body], precision=precision, grid=grid)
    )
    sim = augmpm.Simulation(scene, "naive", threads=1)
    state = sim.checkpoint()
    x = np.asarray(state["x"], dtype=np.float64)
    omega, v0, centre = np.array([0.3, -0.5, 0.8]), np.array([0.2, -0.1, 0.05]), np.array([0.5, 0.5, 0.5])
    spin = np.array([[0.0, -omega[2], omega[1]], [omega[2], 0.0, -omega[0]], [-omega[1], omega[0], 0.0]])
    rigid = v0 + (x - centre) @ spin.T
    sim.restore(state | {"v": rigid, "c": np.broadcast_to(spin, (len(x), 3, 3)).copy()})
    sim.step(1)
    after = sim.checkpoint()
    assert np.abs(after["v"] - rigid).max() < tol_v
    assert np.abs(after["c"] - spin).max() < tol_c


def test_a_3d_scene_beyond_the_memory_limit_is_refused(monkeypatch):
    """With AUGMPM_MEMORY_LIMIT below a 3D scene's estimate, building it raises SceneError naming the key
    that drives the estimate, before allocating."""
    monkeypatch.setenv("AUGMPM_MEMORY_LIMIT", "1M")
    with pytest.raises(augmpm.SceneError) as e:
        augmpm.Simulation(augmpm.Scene3.from_dict(_tank(grid={"domain": [1.0, 1.0, 1.0], "resolution": 64})))
    assert e.value.key in ("grid.resolution", "bodies[0].seeding")


def test_walls_far_from_the_domain_or_sampled_too_finely_are_refused():
    """A 3D wall more than a domain size from the box, or walls that would take more than 5e7 boundary
    points, are refused naming the key, before anything is sampled."""
    far = {"type": "sphere", "center": [0.5, 0.5, 0.5], "radius": 1e3}
    with pytest.raises(augmpm.SceneError) as e:
        augmpm.Simulation(augmpm.Scene3.from_dict(_tank(walls=[far])))
    assert e.value.key == "walls[0]"
    # 200 cells, points 0.06 h apart: about 1.3e8 points on the box and the tank.
    fine = augmpm.Scene3.from_dict(
        _tank(grid={"domain": [1.0, 1.0, 1.0], "resolution": 200}, augmented={"spacing": 0.06})
    )
    with pytest.raises(augmpm.SceneError) as e:
        augmpm.Simulation(fine)
    assert e.value.key == "augmented.spacing"


def test_a_refused_restore_changes_nothing():
    """A checkpoint whose wall rows do not fit the scene is refused naming them, and the simulation goes on
    exactly as if the restore had not been tried."""
    scene = augmpm.Scene3.from_dict(_tank())
    sim, twin = augmpm.Simulation(scene), augmpm.Simulation(scene)
    sim.step(30)
    twin.step(30)
    state = sim.checkpoint()
    state["wall_impulse"] = np.zeros((5, 3))
    with pytest.raises(augmpm.SceneError, match="wall_impulse"):
        sim.restore(state)
    posed = sim.checkpoint()
    posed["wall_pose"] = np.array([[0.0, sim.time, 0.0, 0.0, 0.0, 0.1, 0.0, 0.0]])
    with pytest.raises(augmpm.SceneError, match=r"shape \[1, 14\]"):
        sim.restore(posed)
    # Thirteen numbers, but the wall moves 1 km/s.
    posed["wall_pose"] = np.array([[0.0, sim.time, 0, 0, 0, 0, 0, 0, 1e3, 0, 0, 0, 0, 0]])
    with pytest.raises(augmpm.SceneError, match="cells in a step"):
        sim.restore(posed)
    sim.step(30)
    twin.step(30)
    assert np.array_equal(sim.positions, twin.positions)


def test_a_3d_checkpoint_written_before_3d_poses_restores():
    """3D checkpoints written before 3D walls could be posed hold an empty ``wall_pose`` of 8 columns (the
    2D width): it restores as no posed wall."""
    scene = augmpm.Scene3.from_dict(_tank())
    sim = augmpm.Simulation(scene)
    sim.step(5)
    state = sim.checkpoint()
    state["wall_pose"] = np.zeros((0, 8))
    again = augmpm.Simulation(scene)
    again.restore(state)
    sim.step(5)
    again.step(5)
    assert np.array_equal(again.positions, sim.positions)
