"""Triangle meshes as 3D walls and bodies (``type = "mesh"``, ``shape = "mesh"``): read from OBJ, STL and PLY
files through meshio or given inline, checked closed and oriented, and acting as the same wall as the
primitive they triangulate."""

from __future__ import annotations

import math

import meshio
import numpy as np
import pytest
import tomli_w

import augmpm
from augmpm.validation import incline3d

FLUID = {"type": "fluid", "density": 1000.0, "stiffness": 1e4, "viscosity": 1.0}


def _cube() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The unit cube about the origin: its vertices, its triangles (counter-clockwise from outside) and
    its faces as quads."""
    v = np.array([[c & 1, (c >> 1) & 1, (c >> 2) & 1] for c in range(8)], dtype=float) - 0.5
    quads = np.array([[0, 4, 6, 2], [1, 3, 7, 5], [0, 1, 5, 4], [2, 6, 7, 3], [0, 2, 3, 1], [4, 5, 7, 6]])
    triangles = np.array([t for q in quads for t in ([q[0], q[1], q[2]], [q[0], q[2], q[3]])])
    return v, triangles, quads


def _scene(wall: dict, body: dict) -> dict:
    return {
        "grid": {"domain": [1.0, 1.0, 1.0], "resolution": 16},
        "time": {"dt": 1e-3, "steps": 100, "output_interval": 50},
        "wall_condition": "slip",
        "walls": [wall],
        "bodies": [{**body, "material": FLUID}],
    }


def test_mesh_files_in_obj_stl_and_ply_give_the_particles_of_the_inline_mesh(tmp_path):
    """The same cube written as OBJ (quads, split in two), binary STL (each triangle with its own vertices,
    welded) and PLY, named relative to the scene file, builds bitwise the same simulation as the cube given
    inline; a mesh body seeds bitwise the particles of the box body it triangulates."""
    v, t, quads = _cube()
    meshio.write(tmp_path / "cube.obj", meshio.Mesh(v, [("quad", quads)]))
    meshio.write(tmp_path / "cube.stl", meshio.Mesh(v, [("triangle", t)]), binary=True)
    meshio.write(tmp_path / "cube.ply", meshio.Mesh(v, [("triangle", t)]))
    wall = {"type": "mesh", "scale": 0.3, "position": [0.5, 0.2, 0.5], "angle": 0.4, "axis": [1.0, 2.0, 0.5]}
    body = {"shape": "mesh", "scale": 0.2, "position": [0.5, 0.7, 0.5]}
    inline = {"vertices": v.tolist(), "triangles": t.tolist()}
    reference = augmpm.Simulation(augmpm.Scene3.from_dict(_scene({**wall, **inline}, {**body, **inline})))
    reference.step(20)
    box = {"shape": "box", "min": [0.4, 0.6, 0.4], "max": [0.6, 0.8, 0.6]}
    as_box = augmpm.Simulation(augmpm.Scene3.from_dict(_scene({**wall, **inline}, box)))
    assert np.array_equal(as_box.positions, augmpm.Simulation(reference.scene).positions)
    for name in ("cube.obj", "cube.stl", "cube.ply"):
        path = tmp_path / f"{name}.toml"
        data = _scene({**wall, "file": name}, {**body, "file": name})
        path.write_text(tomli_w.dumps(data))
        sim = augmpm.Simulation(augmpm.load_scene(path))
        sim.step(20)
        assert np.array_equal(sim.positions, reference.positions), name
        assert np.array_equal(sim.boundary_points, reference.boundary_points), name


@pytest.mark.parametrize(
    ("change", "key", "reason"),
    [
        (lambda v, t: (v, t[:-1]), "walls[0].triangles", "not closed"),
        (lambda v, t: (v, t[:, ::-1]), "walls[0].triangles", "face inward"),
        (lambda v, t: (v, np.vstack([t[:1, [0, 2, 1]], t[1:]])), "walls[0].triangles", "consistently oriented"),
        (lambda v, t: (v, t + 1), "walls[0].triangles", "names vertex 8"),
        (lambda v, t: (v[:, :2], t), "walls[0].vertices", "too few items"),
    ],
)
def test_bad_meshes_are_refused_naming_the_key(change, key, reason):
    """An open mesh, one facing inward, one with a triangle turned over, an index past the vertices and
    two-component vertices are refused with SceneError naming the key and why."""
    v, t, _ = _cube()
    v, t = change(v, t)
    wall = {"type": "mesh", "vertices": v.tolist(), "triangles": t.tolist(), "scale": 0.3, "position": [0.5] * 3}
    ball = {"shape": "sphere", "center": [0.2] * 3, "radius": 0.1}
    with pytest.raises(augmpm.SceneError) as e:
        augmpm.Simulation(augmpm.Scene3.from_dict(_scene(wall, ball)))
    assert e.value.key.startswith(key) and reason in e.value.reason, (e.value.key, e.value.reason)


def test_unreadable_mesh_files_are_refused_naming_the_key(tmp_path):
    """A missing file, a file that is no mesh and one without triangles: SceneError naming ``file``."""
    (tmp_path / "lines.obj").write_text("v 0 0 0\nv 1 0 0\nl 1 2\n")
    (tmp_path / "junk.stl").write_bytes(b"\x00" * 10)
    body = {"shape": "sphere", "center": [0.2] * 3, "radius": 0.1}
    for name, reason in [("nothing.obj", "cannot read"), ("lines.obj", "no triangles"), ("junk.stl", "cannot read")]:
        path = tmp_path / "scene.toml"
        path.write_text(tomli_w.dumps(_scene({"type": "mesh", "file": name}, body)))
        with pytest.raises(augmpm.SceneError) as e:
            augmpm.load_scene(path)
        assert e.value.key == "walls[0].file" and reason in e.value.reason, (name, e.value.reason)


def test_a_ball_slides_on_a_mesh_as_on_the_plane_it_triangulates():
    """A ball on a frictionless slab given as a mesh (a box of 12 triangles whose top face is the plane at a
    compound angle of the 3D incline validation, 20°) accelerates at g sin θ within 1% and stays out of it,
    as on the exact plane: the mesh's faces, crease edges and Poisson-disk boundary points make the same
    wall (24 cells per metre)."""
    angle = 20.0
    scene, t = incline3d._scene(angle, 24)
    plane = scene["walls"][0]
    n = np.array(plane["normal"])
    # The slab: a box below the plane, turned so that its local y is the plane's normal.
    v, triangles, _ = _cube()
    axis = np.cross([0.0, 1.0, 0.0], n)
    slab = {
        "type": "mesh",
        "vertices": (v * [1.3, 0.4, 1.3]).tolist(),
        "triangles": triangles.tolist(),
        "position": (np.array(plane["point"]) - 0.2 * n).tolist(),
        "axis": axis.tolist(),
        "angle": math.asin(np.linalg.norm(axis)),
        "side": "outside",
    }
    a_exact = incline3d.G * math.sin(math.radians(angle))
    t_end = math.sqrt(2 * 0.3 / a_exact)
    times = list(np.linspace(0.15 * t_end, t_end, 16))
    accel = {}
    for wall in ("plane", "mesh"):
        scene["walls"] = [plane if wall == "plane" else slab]
        s, outside = incline3d._slide(scene, t, "augmented", times)
        accel[wall] = 2 * np.polyfit(times, s, 2)[0]
        assert outside == 0, wall
    assert abs(accel["mesh"] / a_exact - 1) < 0.01, accel
    assert abs(accel["mesh"] / accel["plane"] - 1) < 0.005, accel


def test_fluid_poured_onto_a_torus_mesh_leaks_with_naive_walls_only():
    """scenes/mesh/fluid_torus (fluid poured onto a torus of 1,600 triangles tipped 0.3 rad, 32 cells,
    0.8 s; its mesh file read relative to the scene): the augmented grid keeps 0 particles outside at every
    40th step; the naive walls let particles through (1,693 at most when measured)."""
    scene = augmpm.load_scene("mesh/fluid_torus")
    most = {}
    for method in ("naive", "augmented"):
        sim = augmpm.Simulation(scene, method, threads=2)
        total = scene.time.total_steps(sim.dt)
        most[method] = 0
        while sim.steps_done < total:
            sim.step(min(40, total - sim.steps_done))
            most[method] = max(most[method], sim.metrics()["n_outside"])
    assert most["augmented"] == 0
    assert most["naive"] > 100


def test_water_runs_off_a_thin_plate_and_around_it():
    """A thin wall (`thickness`, three cells) around an open plate of two triangles tilted in no coordinate
    plane: water dropped on it runs off and around it with 0 particles inside the plate at every 20th step
    with the augmented grid, while the naive walls let most of it through (423 of 460 when measured)."""
    res = 24
    h = 1.0 / res
    c, s = math.cos(0.35), math.sin(0.35)
    turn = np.array([[1, 0, 0], [0, math.cos(0.2), -math.sin(0.2)], [0, math.sin(0.2), math.cos(0.2)]])
    turn = turn @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    centre = np.array([0.5, 0.4, 0.5])
    plate = [
        (centre + turn @ np.array([u, 0.0, v])).tolist()
        for u, v in [(-0.3, -0.25), (0.3, -0.25), (0.3, 0.25), (-0.3, 0.25)]
    ]
    scene = {
        "seed": 2,
        "gravity": [0.0, -9.81, 0.0],
        "wall_condition": "slip",
        "grid": {"domain": [1.0, 1.0, 1.0], "resolution": res},
        "time": {"cfl": 0.4, "end": 0.6, "output_interval": 20},
        "walls": [{"type": "mesh", "vertices": plate, "triangles": [[0, 1, 2], [0, 2, 3]], "thickness": 3 * h}],
        "bodies": [{"shape": "sphere", "center": [0.45, 0.7, 0.5], "radius": 0.1, "material": FLUID}],
    }
    most = {}
    for method in ("naive", "augmented"):
        sim = augmpm.Simulation(augmpm.Scene3.from_dict(scene), method)
        total = sim.scene.time.total_steps(sim.dt)
        most[method] = 0
        while sim.steps_done < total:
            sim.step(min(20, total - sim.steps_done))
            most[method] = max(most[method], sim.metrics()["n_outside"])
    assert most["augmented"] == 0 and most["naive"] > 100, most
    bad = {**scene, "walls": [{**scene["walls"][0], "side": "inside"}]}
    with pytest.raises(augmpm.SceneError) as e:
        augmpm.Simulation(augmpm.Scene3.from_dict(bad))
    assert e.value.key == "walls[0].side"
