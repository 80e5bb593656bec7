"""One source per scene key: the engine's schema. The Python models are built from it, agree with the
engine's own checks at every bound, and the README's scene reference is generated from it."""

from __future__ import annotations

import copy
import re
from pathlib import Path
from typing import Any

import pytest

import augmpm
from augmpm import _core
from augmpm.reference import scene_reference
from augmpm.scene import SCHEMA, SCHEMA3, Scene, Scene3

README = Path(__file__).resolve().parents[1] / "README.md"

_MATERIALS = {
    "fluid": {"type": "fluid", "density": 1000.0, "stiffness": 1e4},
    "elastic": {"type": "elastic", "density": 1000.0, "youngs_modulus": 1e4, "poisson_ratio": 0.3},
    "stvk": {"type": "stvk", "density": 1000.0, "youngs_modulus": 1e4, "poisson_ratio": 0.3},
    "snow": {"type": "snow", "density": 400.0, "youngs_modulus": 1e4, "poisson_ratio": 0.2},
}
_BODIES = {
    "box": {"shape": "box", "min": [0.3, 0.3], "max": [0.5, 0.5]},
    "circle": {"shape": "circle", "center": [0.4, 0.4], "radius": 0.1},
    "polygon": {"shape": "polygon", "vertices": [[0.3, 0.3], [0.5, 0.3], [0.4, 0.5]]},
}
_WALLS = [
    {"type": "polygon", "vertices": [[0.05, 0.05], [0.95, 0.05], [0.95, 0.95], [0.05, 0.95]]},
    {"type": "circle", "center": [0.8, 0.8], "radius": 0.05},
]
_RIGID = [
    {"shape": "polygon", "vertices": [[0.6, 0.2], [0.7, 0.2], [0.7, 0.3], [0.6, 0.3]], "density": 500.0},
    {"shape": "circle", "center": [0.2, 0.8], "radius": 0.05, "mass": 2.0},
]


def _scenes() -> list[dict[str, Any]]:
    """Valid scenes that together hold every kind of table the schema declares."""
    scenes = []
    shapes = [*_BODIES.values(), _BODIES["box"]]
    for material, body in zip(_MATERIALS.values(), shapes, strict=True):
        scenes.append(
            {
                "grid": {"domain": [1.0, 1.0], "resolution": 16},
                "time": {"dt": 1e-4, "steps": 2, "output_interval": 1},
                "walls": copy.deepcopy(_WALLS),
                "bodies": [{**copy.deepcopy(body), "material": dict(material), "seeding": {"per_cell": 4}}],
                "rigid_bodies": copy.deepcopy(_RIGID),
            }
        )
    return scenes


_BODIES3 = [
    {"shape": "box", "min": [0.3, 0.3, 0.3], "max": [0.5, 0.5, 0.5]},
    {"shape": "sphere", "center": [0.4, 0.4, 0.4], "radius": 0.1},
    {"shape": "cylinder", "center": [0.4, 0.4, 0.4], "axis": [0.0, 1.0, 0.0], "radius": 0.1, "length": 0.2},
    {"shape": "box", "min": [0.3, 0.3, 0.3], "max": [0.5, 0.5, 0.5]},
]
_WALLS3 = [
    {"type": "box", "center": [0.5, 0.5, 0.5], "size": [0.9, 0.9, 0.9], "axis": [1.0, 1.0, 0.0], "angle": 0.1},
    {"type": "plane", "point": [0.5, 0.1, 0.5], "normal": [0.0, 1.0, 0.1]},
    {"type": "sphere", "center": [0.8, 0.8, 0.8], "radius": 0.05},
    {"type": "cylinder", "center": [0.2, 0.8, 0.2], "axis": [0.0, 0.0, 1.0], "radius": 0.05, "length": 0.1},
]


_RIGID3 = [
    {"shape": "box", "center": [0.6, 0.5, 0.5], "size": [0.1, 0.1, 0.1], "axis": [1.0, 0.0, 0.0], "angle": 0.3,
     "density": 500.0},
    {"shape": "sphere", "center": [0.3, 0.6, 0.3], "radius": 0.05, "mass": 0.2},
    {"shape": "cylinder", "center": [0.6, 0.7, 0.3], "axis": [1.0, 0.0, 0.0], "radius": 0.04, "length": 0.1,
     "density": 400.0},
]  # fmt: skip


def _scenes3() -> list[dict[str, Any]]:
    """Valid 3D scenes that together hold every kind of table the 3D schema declares."""
    return [
        {
            "grid": {"domain": [1.0, 1.0, 1.0], "resolution": 8},
            "time": {"dt": 1e-4, "steps": 2, "output_interval": 1},
            "walls": copy.deepcopy(_WALLS3),
            "bodies": [{**copy.deepcopy(body), "material": dict(material), "seeding": {"per_cell": 8}}],
            "rigid_bodies": copy.deepcopy(_RIGID3),
        }
        for material, body in zip(_MATERIALS.values(), _BODIES3, strict=True)
    ]


def _resolve(schema: dict[str, Any]) -> dict[str, Any]:
    ref = schema.get("$ref")
    return {**_DEFS[ref.rsplit("/", 1)[-1]], **schema} if ref else schema


_DEFS = {**SCHEMA3["$defs"], **SCHEMA["$defs"]}


def _bounded_leaves(schema: dict[str, Any], value: Any, path: list[Any]):
    """Yields (path, bound keyword, bound) for every bounded number the scene `value` may hold at `path`,
    optional keys included."""
    schema = _resolve(schema)
    if "anyOf" in schema:
        schema = _resolve(next(o for o in schema["anyOf"] if o.get("type") != "null"))
    properties = dict(schema.get("properties", {}))
    options = schema.get("oneOf")
    if options and isinstance(value, dict) and not all("const" in o for o in options):
        tag = next(k for k, p in options[0]["properties"].items() if "const" in p)
        option = next(o for o in options if o["properties"][tag]["const"] == value.get(tag))
        properties.update(option["properties"])
    kinds = schema.get("type")
    kinds = [kinds] if isinstance(kinds, str) else list(kinds or [])
    if properties:
        for key, prop in properties.items():
            yield from _bounded_leaves(prop, (value or {}).get(key) if isinstance(value, dict) else None, [*path, key])
    elif "array" in kinds and "items" in schema:
        items = value if isinstance(value, list) and value else [None]
        for i, item in enumerate(items):
            yield from _bounded_leaves(schema["items"], item, [*path, i])
    elif "number" in kinds or "integer" in kinds:
        for bound in ("minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum"):
            if bound in schema and not (bound == "maximum" and schema[bound] >= 2**63 - 1):
                yield path, bound, schema[bound], "integer" in kinds


def _outside(bound: str, limit: float, integer: bool) -> float:
    step = 1 if integer else max(abs(limit), 1.0) * 1e-6
    return {"minimum": limit - step, "maximum": limit + step}.get(bound, limit)


def _set(data: dict[str, Any], path: list[Any], value: Any) -> str:
    node = data
    for part in path[:-1]:
        if isinstance(part, int):
            while len(node) <= part:
                node.append(None)
            if node[part] is None:
                node[part] = [0.0, 0.0]
        elif part not in node:
            node[part] = {}
        node = node[part]
    if isinstance(node, list) and path[-1] >= len(node):
        node.extend([0.0] * (path[-1] + 1 - len(node)))
    node[path[-1]] = value
    return "".join(f"[{p}]" if isinstance(p, int) else (f".{p}" if i else p) for i, p in enumerate(path))


def _cases(schema: dict[str, Any], scenes: list[dict[str, Any]]) -> list[tuple[str, dict[str, Any], str]]:
    cases: dict[str, tuple[str, dict[str, Any], str]] = {}
    for scene in scenes:
        for path, bound, limit, integer in _bounded_leaves(schema, scene, []):
            data = copy.deepcopy(scene)
            key = _set(data, path, _outside(bound, limit, integer))
            cases.setdefault(f"{key} {bound}", (key, data, bound))
    return sorted(cases.values(), key=lambda c: (c[0], c[2]))


CASES = _cases(SCHEMA, _scenes())
CASES3 = _cases(SCHEMA3, _scenes3())


def test_every_bound_is_exercised():
    """The cases reach the bounds of every table: materials, shapes, walls, seeding, time, grid, augmented."""
    keys = {key for key, _, _ in CASES}
    for expected in (
        "bodies[0].material.poisson_ratio",
        "bodies[0].material.jp_min",
        "bodies[0].material.min_pressure",
        "bodies[0].radius",
        "bodies[0].scale",
        "bodies[0].seeding.per_cell",
        "walls[1].radius",
        "time.cfl",
        "grid.domain[0]",
        "augmented.delta",
    ):
        assert expected in keys, sorted(keys)
    assert len(CASES) > 30


@pytest.mark.parametrize(
    ("key", "data", "bound"),
    CASES + CASES3,
    ids=[f"{c[0]}-{c[2]}" for c in CASES] + [f"3d-{c[0]}-{c[2]}" for c in CASES3],
)
def test_python_and_the_engine_refuse_the_same_value_naming_the_same_key(key, data, bound):
    """Just outside each declared bound (of 2D and 3D scenes), the Python models and the engine (which runs
    any scene, also one built without Python) both refuse the value and name the same dotted key: the two
    checks read one declaration."""
    with pytest.raises(augmpm.SceneError) as python_error:
        augmpm.scene.scene_class(data).from_dict(data)
    assert python_error.value.key == key, str(python_error.value)
    with pytest.raises(augmpm.SceneError) as engine_error:
        _core.check_scene(augmpm.scene.json.dumps(data))
    assert engine_error.value.key == key, str(engine_error.value)


def test_the_3d_cases_reach_every_3d_table():
    keys = {k for k, _, _ in CASES3}
    assert {"walls[0].size[0]", "walls[3].length", "bodies[0].seeding.per_cell", "grid.resolution"} <= keys


def test_valid_scenes_pass_both_checks():
    for data in _scenes():
        _core.check_scene(Scene.from_dict(data).to_json())
    for data in _scenes3():
        _core.check_scene(Scene3.from_dict(data).to_json())


def test_defaults_come_from_the_engine():
    """A scene that gives only what is required gets the engine's defaults (the snow parameters, δ)."""
    scene = Scene.from_dict(_scenes()[3])
    snow = scene.bodies[0].material
    declared = SCHEMA["$defs"]["Material"]["oneOf"][3]["properties"]
    defaults = {k: v["default"] for k, v in declared.items() if "default" in v}
    expected = {"critical_compression": 0.025, "critical_stretch": 0.0075, "hardening": 10.0}
    expected |= {"jp_min": 0.6, "jp_max": 20.0}
    assert defaults == expected
    assert {k: getattr(snow, k) for k in defaults} == defaults
    assert scene.augmented.delta == SCHEMA["$defs"]["AugmentedSpec"]["properties"]["delta"]["default"] == 0.25


def test_the_readme_scene_reference_is_generated_from_the_schema():
    """The README's scene reference is `augmpm schema --markdown`, byte for byte (regenerate it with
    `augmpm schema --markdown` when a key changes)."""
    text = README.read_text(encoding="utf-8")
    match = re.search(r"<!-- scene-reference: generated[^\n]*-->\n(.*?)<!-- scene-reference: end -->", text, re.S)
    assert match, "README.md has no generated scene reference"
    assert match.group(1) == scene_reference()


def test_schema_command_prints_the_json_schema(capsys):
    from augmpm.cli import main

    assert main(["schema"]) == 0
    assert augmpm.scene.json.loads(capsys.readouterr().out) == SCHEMA
    assert main(["schema", "--markdown"]) == 0
    assert capsys.readouterr().out == scene_reference()
