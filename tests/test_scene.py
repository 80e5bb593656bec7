"""Scene files: every class of bad input names its key, raises SceneError and exits with code 2."""

from __future__ import annotations

import copy

import numpy as np
import pytest

import augmpm
from augmpm.cli import main

from .conftest import SCENES


def _mutate(data: dict, path: str, value) -> dict:
    node = data
    parts = path.split(".")
    for p in parts[:-1]:
        node = node[int(p)] if isinstance(node, list) else node[p]
    last = parts[-1]
    if isinstance(node, list):
        node[int(last)] = value
    else:
        node[last] = value
    return data


BAD = [
    ("unknown key", "grid.resolutoin", 16, "grid.resolutoin", "unknown key"),
    ("misspelled key", "time.stpes", 10, "time.stpes", "unknown key (did you mean 'steps'?)"),
    ("wrong type", "time.steps", "many", "time.steps", "integer"),
    ("negative density", "bodies.0.material.density", -1.0, "bodies[0].material.density", "greater than 0"),
    ("poisson ratio 0.5", "bodies.0.material.poisson_ratio", 0.5, "bodies[0].material.poisson_ratio", "less than 0.5"),
    ("unknown material", "bodies.0.material.type", "jelly", "bodies[0].material", "type"),
    ("NaN gravity", "gravity", [float("nan"), 0.0], "gravity[0]", "finite"),
    (
        "self-intersecting wall",
        "walls.0.vertices",
        [[0.1, 0.1], [0.9, 0.9], [0.9, 0.1], [0.1, 0.9]],
        "walls[0].vertices",
        "self-intersecting",
    ),
    (
        "repeated vertex",
        "walls.0.vertices",
        [[0.05, 0.05], [0.95, 0.05], [0.95, 0.05], [0.95, 0.95], [0.05, 0.95]],
        "walls[0].vertices",
        "vertices 1 and 2 are the same point",
    ),
    (
        "clockwise wall",
        "walls.0.vertices",
        [[0.05, 0.95], [0.95, 0.95], [0.95, 0.05], [0.05, 0.3]],
        "walls[0].vertices",
        "clockwise",
    ),
    ("body outside the walls", "bodies.0.min", [0.02, 0.02], "bodies[0]", "outside the walls"),
    ("body outside the domain", "bodies.0.max", [1.2, 0.8], "bodies[0]", "outside the walls"),
    ("both dt and cfl", "time.cfl", 0.5, "time", "exactly one of dt and cfl"),
    ("grid height not whole cells", "grid.domain", [1.0, 0.51], "grid.domain", "whole number"),
    ("grid too large for memory", "grid.resolution", 20000, "grid.resolution", "MB"),
    ("grid height overflows", "grid.domain", [1.0, 1e300], "grid.resolution", "MB"),
    (
        "wall far outside the domain",
        "walls.0",
        {"type": "circle", "center": [0.5, 0.5], "radius": 1e12},
        "walls[0]",
        "far",
    ),
    (
        "seeding too dense for memory",
        "bodies.0.seeding",
        {"spacing": 1e-5},
        "bodies[0].seeding",
        "of memory are available",
    ),
]


@pytest.mark.parametrize(("what", "path", "value", "key", "reason"), BAD, ids=[b[0] for b in BAD])
def test_bad_scene_is_named(small_scene, what, path, value, key, reason):
    data = _mutate(small_scene, path, value)
    with pytest.raises(augmpm.SceneError) as err:
        augmpm.Simulation(augmpm.Scene.from_dict(data))
    assert err.value.key == key, str(err.value)
    assert reason in str(err.value)


@pytest.mark.parametrize(("what", "path", "value", "key", "reason"), BAD, ids=[b[0] for b in BAD])
def test_bad_scene_exits_2(small_scene, write_scene, tmp_path, capsys, what, path, value, key, reason):
    scene = write_scene(_mutate(small_scene, path, value))
    out = tmp_path / "out"
    assert main(["run", str(scene), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert key in err and reason in err
    assert not (out / "metrics.csv").exists()


def test_scenes_built_or_changed_in_code_report_bad_values_as_scene_errors(small_scene):
    """`augmpm.Scene(...)` and an assignment to a scene's field raise SceneError naming the dotted key, as a
    loaded scene does, not pydantic's ValidationError."""
    scene = augmpm.Scene(**small_scene)
    data = _mutate(small_scene, "bodies.0.material.poisson_ratio", 0.5)
    with pytest.raises(augmpm.SceneError) as err:
        augmpm.Scene(**data)
    assert err.value.key == "bodies[0].material.poisson_ratio", str(err.value)
    with pytest.raises(augmpm.SceneError) as err:
        scene.time.steps = -1
    assert err.value.key == "steps" and "greater than or equal to 0" in str(err.value), str(err.value)


def test_did_you_mean_looks_in_the_table_of_the_misspelled_key(small_scene):
    """A misspelled key is matched against the keys of its own table: a material key is suggested inside a
    material, and a key of another table (`stiffness` is no key of a box body) is never suggested."""
    data = copy.deepcopy(small_scene)
    data["bodies"][0]["material"]["densty"] = 1.0
    with pytest.raises(augmpm.SceneError) as err:
        augmpm.Scene.from_dict(data)
    assert str(err.value) == "bodies[0].material.densty: unknown key (did you mean 'density'?)"
    data = copy.deepcopy(small_scene)
    data["grid"]["stiffnes"] = 1.0
    with pytest.raises(augmpm.SceneError) as err:
        augmpm.Scene.from_dict(data)
    assert str(err.value) == "grid.stiffnes: unknown key"


def test_a_polygon_closed_by_repeating_its_first_vertex_is_accepted(small_scene):
    """A wall polygon that ends on its first vertex (closed, as many tools write polygons) builds and runs the
    same simulation as without the repeat, bit for bit."""
    vertices = small_scene["walls"][0]["vertices"]
    closed = _mutate(copy.deepcopy(small_scene), "walls.0.vertices", [*vertices, vertices[0]])
    assert len(closed["walls"][0]["vertices"]) == len(small_scene["walls"][0]["vertices"]) + 1
    runs = [augmpm.Simulation(augmpm.Scene.from_dict(s), "augmented") for s in (small_scene, closed)]
    assert np.array_equal(runs[0].boundary_points, runs[1].boundary_points)
    for sim in runs:
        sim.step(200)
    assert runs[0].metrics()["kinetic_energy"] > 0
    assert np.array_equal(runs[0].positions, runs[1].positions)


def test_unreadable_inputs_exit_2(tmp_path, capsys, write_scene, small_scene):
    assert main(["run", str(tmp_path / "missing.toml")]) == 2
    assert "cannot read scene file" in capsys.readouterr().err
    broken = tmp_path / "broken.toml"
    broken.write_text("grid = [", encoding="utf-8")
    assert main(["run", str(broken)]) == 2
    assert "not valid TOML" in capsys.readouterr().err
    scene = write_scene(small_scene)
    assert main(["run", str(scene), "--set", "bodies[3].velocity=[1,0]"]) == 2
    assert "not an index" in capsys.readouterr().err
    assert main(["run", str(scene), "--method", "magic"]) == 2
    binary = tmp_path / "binary.toml"
    binary.write_bytes(b"\xff\xfe\x00garbage")
    assert main(["run", str(binary)]) == 2
    assert "not UTF-8" in capsys.readouterr().err
    assert main(["run", str(scene), "--out", str(binary)]) == 2
    assert "not a directory" in capsys.readouterr().err
    assert main(["interp-test", "--resolution", "4"]) == 2


def test_overrides_reach_the_scene(small_scene, write_scene):
    path = write_scene(small_scene)
    scene = augmpm.load_scene(path, ["time.steps=7", "bodies.0.material.youngs_modulus=2e5", "wall_condition=slip"])
    assert scene.time.steps == 7
    assert scene.bodies[0].material.youngs_modulus == 2e5
    assert scene.wall_condition == "slip"


def test_set_with_nothing_after_the_equals_sign_removes_a_key(small_scene, write_scene):
    """`--set KEY=` removes KEY, so that a scene can switch from one of two exclusive keys to the other (cfl to
    dt); removing a key the scene does not have is an error naming it."""
    small_scene["time"].pop("dt", None)
    small_scene["time"]["cfl"] = 0.4
    path = write_scene(small_scene)
    scene = augmpm.load_scene(path, ["time.cfl=", "time.dt=1e-4"])
    assert scene.time.dt == 1e-4 and scene.time.cfl is None
    with pytest.raises(augmpm.SceneError) as err:
        augmpm.load_scene(path, ["time.nothing="])
    assert err.value.key == "time.nothing" and "no such key" in str(err.value)


def test_end_time_sets_the_number_of_steps(small_scene, tmp_path):
    """`time.end` (s) instead of `time.steps`: the run takes ⌈end / dt⌉ steps (an end a whole number of steps
    away, up to rounding, takes that number); giving both, or neither, names `time`."""
    small_scene["time"].pop("steps")
    small_scene["time"].update(dt=1e-3, end=0.01, output_interval=5)
    result = augmpm.run_scene(augmpm.Scene.from_dict(small_scene), tmp_path / "a", progress=False, render=False)
    assert result.final_metrics["step"] == 10
    time = augmpm.Scene.from_dict(small_scene).time
    assert time.model_copy(update={"end": 0.0105}).total_steps(1e-3) == 11
    for update in ({"steps": 5}, {"end": None}):
        data = copy.deepcopy(small_scene)
        data["time"].update(update)
        data["time"] = {k: v for k, v in data["time"].items() if v is not None}
        with pytest.raises(augmpm.SceneError, match="exactly one of steps and end") as err:
            augmpm.Scene.from_dict(data)
        assert err.value.key == "time"


def test_dt_above_stable_bound_warns(small_scene):
    small_scene["time"]["dt"] = 0.05
    sim = augmpm.Simulation(augmpm.Scene.from_dict(small_scene))
    assert sim.dt > sim.stable_dt
    assert any("exceeds the stable bound" in w for w in sim.warnings)


def test_cfl_sets_dt_from_the_stable_bound(small_scene):
    del small_scene["time"]["dt"]
    small_scene["time"]["cfl"] = 0.4
    sim = augmpm.Simulation(augmpm.Scene.from_dict(small_scene))
    assert sim.dt == pytest.approx(0.4 * sim.stable_dt, rel=1e-12)
    assert sim.warnings == []


@pytest.mark.parametrize("path", sorted(SCENES.rglob("*.toml")), ids=lambda p: p.stem)
def test_shipped_scenes_build(path):
    sim = augmpm.Simulation(augmpm.load_scene(path))
    assert sim.num_particles > 0
    assert sim.metrics()["n_outside"] == 0
    assert sim.warnings == []


def test_resolved_scene_round_trips(small_scene, tmp_path):
    scene = augmpm.Scene.from_dict(small_scene)
    again = augmpm.Scene.from_dict(__import__("tomllib").loads(scene.to_toml()))
    assert again == scene
