"""Fuzzed scene files either run with finite state or are refused by an augmpm error naming their key.

Hypothesis mutates a few valid base scenes (wrong types, missing and unknown keys, NaN/inf/huge/tiny numbers,
degenerate polygons, bodies outside the walls, walls that enclose nothing, ...), writes each as TOML and loads,
builds (both methods, one thread) and steps it. Allowed outcomes: a run whose positions, velocities, densities
and energy stay finite; a ``SceneError`` whose ``key`` names a key of the scene; a ``SimulationError`` with
integer ``step`` and ``particle``. Anything else -- another exception type, a Rust panic, a crash, a hang, a
loaded scene that differs from the file -- fails the case, with the scene's TOML in the message.

Cases run in a worker process (restarted after a crash or a hang) under a wall-clock limit and an
address-space limit, so a hang or an abort in the Rust core fails one case instead of the session.

The suite runs a few hundred derandomized (reproducible) examples. Nightly, random and as many as asked::

    AUGMPM_FUZZ_EXAMPLES=20000 python -m pytest tests/test_fuzz.py --hypothesis-show-statistics
"""

from __future__ import annotations

import copy
import datetime
import json
import math
import os
import re
import selectors
import subprocess
import sys
import tempfile
import time
import tomllib
import traceback
import typing
from pathlib import Path

import numpy as np
import pytest
import tomli_w
from hypothesis import HealthCheck, currently_in_test_context, event, example, given, settings
from hypothesis import strategies as st
from pydantic import BaseModel

import augmpm
from augmpm.scene import Scene, Scene3, scene_class

from .conftest import _SMALL, ROOT

# --- budgets --------------------------------------------------------------------------------------------

#: Steps taken by each built simulation.
STEPS = 4
#: Wall-clock limit of one case (load, two builds, two runs); above it the case counts as a hang.
CASE_LIMIT_S = 20.0
#: Valid scenes larger than this are only loaded, not built: the engine accepts grids up to 2**24 nodes and
#: bodies up to 2e7 seeding candidates by design (test_scene.py checks those limits), and building such a scene
#: costs seconds and gigabytes without exercising any check the small scenes miss. Above the engine's own
#: limits the scene is built again, since the refusal is immediate.
BUDGET_NODES, ENGINE_MAX_NODES = 60_000, 2**24
BUDGET_CANDIDATES, ENGINE_MAX_CANDIDATES = 30_000, 20_000_000
#: Address space a worker may add to what it holds after its imports (a backstop: budgeted cases use ~50 MB).
WORKER_EXTRA_BYTES = 3 * 2**30

_NIGHTLY = int(os.environ.get("AUGMPM_FUZZ_EXAMPLES", "0") or 0)


def _fuzz_settings(suite_examples: int) -> settings:
    """Derandomized with ``suite_examples`` in the suite; random with $AUGMPM_FUZZ_EXAMPLES examples nightly."""
    return settings(
        max_examples=_NIGHTLY or suite_examples,
        derandomize=not _NIGHTLY,
        database=None if not _NIGHTLY else settings.default.database,
        deadline=None,
        print_blob=True,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much],
    )


# --- base scenes: small, valid, each a different corner of the schema -----------------------------------

_FLUID = tomllib.loads("""
name = "fluid"
seed = 2
gravity = [0.0, -9.81]
wall_condition = "slip"
augmented = {delta = 0.25, spacing = 0.5}
grid = {domain = [1.0, 0.5], resolution = 16, density_wall_correction = true}
time = {cfl = 0.5, steps = 10, output_interval = 5}

[[walls]]
type = "polygon"
vertices = [[0.05, 0.05], [0.95, 0.1], [0.95, 0.45], [0.05, 0.45]]
condition = "separate"
tangential_speed = 0.1

[[bodies]]
shape = "box"
min = [0.1, 0.12]
max = [0.4, 0.4]
velocity = [0.5, 0.0]
material = {type = "fluid", density = 1000.0, stiffness = 1e4, gamma = 7.0, viscosity = 0.1, min_pressure = -10.0}
seeding = {per_cell = 4}
""")

_CIRCLE = tomllib.loads("""
name = "circle"
gravity = [0.0, -9.81]
grid = {domain = [1.0, 1.0], resolution = 16}
time = {dt = 5e-4, steps = 10, output_interval = 5}

[[walls]]
type = "circle"
center = [0.5, 0.4]
radius = 0.2
side = "outside"
tangential_speed = 1.0

[[walls]]
type = "circle"
center = [0.5, 0.5]
radius = 0.48
side = "inside"
condition = "slip"

[[bodies]]
shape = "circle"
center = [0.5, 0.78]
radius = 0.1
seeding = {spacing = 0.02}

[bodies.material]
type = "snow"
density = 400.0
youngs_modulus = 1.4e5
poisson_ratio = 0.2
critical_compression = 2.5e-2
critical_stretch = 7.5e-3
hardening = 10.0
jp_min = 0.6
jp_max = 20.0
""")

_MULTI = tomllib.loads("""
name = "multi"
seed = 3
gravity = [1.0, -9.81]
wall_condition = "separate"
precision = "f32"
grid = {domain = [2.0, 1.0], resolution = 24}
time = {dt = 2e-4, steps = 10, output_interval = 5}

[[walls]]
type = "polygon"
vertices = [[0.05, 0.05], [1.95, 0.05], [1.95, 0.95], [1.2, 0.95], [1.2, 0.6], [0.05, 0.6]]
velocity = [0.1, 0.0]

[[bodies]]
shape = "polygon"
vertices = [[-0.5, -0.5], [0.5, -0.5], [0.0, 0.5]]
scale = 0.3
center = [0.4, 0.3]
material = {type = "stvk", density = 1000.0, youngs_modulus = 1e5, poisson_ratio = 0.3}

[[bodies]]
shape = "box"
min = [1.3, 0.3]
max = [1.6, 0.8]
velocity = [-1.0, 0.0]
material = {type = "elastic", density = 800.0, youngs_modulus = 5e4, poisson_ratio = 0.25}

[[bodies]]
shape = "circle"
center = [0.9, 0.3]
radius = 0.12
material = {type = "fluid", density = 1000.0, stiffness = 1e4}

[[bodies]]
shape = "box"
min = [1.65, 0.1]
max = [1.9, 0.5]

[bodies.material]
type = "sand"
density = 2200.0
youngs_modulus = 2e5
poisson_ratio = 0.3
friction_angle = 35.0
cohesion = 50.0
""")

_TANK3D = tomllib.loads("""
name = "tank3d"
gravity = [0.0, -9.81, 0.0]
grid = {domain = [1.0, 1.0, 1.0], resolution = 8}
time = {dt = 5e-4, steps = 10, output_interval = 5}
wall_condition = "separate"
wall_friction = 0.2

[[walls]]
type = "box"
center = [0.5, 0.45, 0.5]
size = [0.8, 0.7, 0.8]
axis = [1.0, 0.3, 0.2]
angle = 0.3

[[walls]]
type = "sphere"
center = [0.5, 0.3, 0.5]
radius = 0.1

[[walls]]
type = "cylinder"
center = [0.3, 0.5, 0.7]
axis = [0.0, 1.0, 0.0]
radius = 0.05
length = 0.3

[[bodies]]
shape = "cylinder"
center = [0.5, 0.6, 0.5]
axis = [0.0, 1.0, 0.0]
radius = 0.12
length = 0.1
material = {type = "snow", density = 400.0, youngs_modulus = 1e4, poisson_ratio = 0.2}
""")

BASES = {"small": _SMALL, "fluid": _FLUID, "circle": _CIRCLE, "multi": _MULTI, "tank3d": _TANK3D}


# --- paths into a scene dict ----------------------------------------------------------------------------

Path_ = tuple[str | int, ...]


def _paths(node: object, prefix: Path_ = ()) -> list[Path_]:
    """Every node below ``node``, as key paths, parents before children."""
    items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
    out: list[Path_] = []
    for k, v in items:
        out.append((*prefix, k))
        out.extend(_paths(v, (*prefix, k)))
    return out


def _get(data: object, path: Path_) -> typing.Any:
    for k in path:
        data = data[k]  # type: ignore[index]
    return data


def _set(data: dict, path: Path_, value: object) -> None:
    _get(data, path[:-1])[path[-1]] = value


def _is_number(v: object) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


# --- values ---------------------------------------------------------------------------------------------

SPECIAL_NUMBERS = [
    math.nan, math.inf, -math.inf, -1.0, -1, 0, 0.0, -0.0, 1, 2, 0.5, 1e300, -1e300, 1e-300, 5e-324, 1e6, 1e-6,
    3.5e38, 2**31, 2**32, 2**63 - 1, 2**63, 2**64, -(2**63), 2**70,
]  # fmt: skip
TAGS = [
    "polygon", "circle", "box", "fluid", "elastic", "stvk", "snow", "sand", "sticky", "slip", "separate", "inside",
    "outside", "f32", "f64", "", "Polygon", "FLUID",
]  # fmt: skip
WRONG_TYPES = [
    "x", "1.5", "", "nan", True, False, [], [1.0], [1.0, 2.0, 3.0], [[1.0, 2.0]], ["a", "b"], {}, {"a": 1},
    datetime.date(2024, 1, 1), datetime.time(12, 0),
]  # fmt: skip
UNKNOWN_KEYS = ["foo", "resolutoin", "Type", "densty", "_", "déjà", "x0", "steps_", "bodies2"]

numbers = st.sampled_from(SPECIAL_NUMBERS) | st.floats(allow_nan=True, allow_infinity=True) | st.integers()
# Copied: a later mutation may edit the value in place, and the constants must stay as they are. None cannot be
# written in TOML: such scenes go to Scene.from_dict, as a Python caller would pass them.
bad_values = (numbers | st.sampled_from(WRONG_TYPES) | st.sampled_from(TAGS) | st.none()).map(copy.deepcopy)


def m_replace(draw, data: dict) -> None:
    """A value (leaf or table) becomes a number, a tag or a value of the wrong type."""
    _set(data, draw(st.sampled_from(_paths(data))), draw(bad_values))


def m_number(draw, data: dict) -> None:
    """A number becomes NaN, ±inf, negative, zero, huge or tiny."""
    paths = [p for p in _paths(data) if _is_number(_get(data, p))]
    if paths:
        _set(data, draw(st.sampled_from(paths)), draw(numbers))


def m_delete(draw, data: dict) -> None:
    """A key, required or not, is deleted (or a list item dropped)."""
    path = draw(st.sampled_from(_paths(data)))
    del _get(data, path[:-1])[path[-1]]


def m_unknown_key(draw, data: dict) -> None:
    """A table, the top level included, gains a key the schema does not know."""
    tables = [(), *(p for p in _paths(data) if isinstance(_get(data, p), dict))]
    table = _get(data, draw(st.sampled_from(tables)))
    key = draw(st.sampled_from(UNKNOWN_KEYS) | st.from_regex(r"[a-z_]{1,10}", fullmatch=True))
    if key not in table:
        table[key] = draw(st.sampled_from([1, 1.0, "x", True, [1.0, 2.0], {"a": 1}]).map(copy.deepcopy))


def m_tag(draw, data: dict) -> None:
    """A string (a tag, a condition, the name) becomes another tag."""
    paths = [p for p in _paths(data) if isinstance(_get(data, p), str)]
    if paths:
        _set(data, draw(st.sampled_from(paths)), draw(st.sampled_from(TAGS)))


def m_list(draw, data: dict) -> None:
    """A list (a vector, the vertices, the walls, the bodies) is emptied, cut short or grown."""
    paths = [p for p in _paths(data) if isinstance(_get(data, p), list)]
    if not paths:
        return
    path = draw(st.sampled_from(paths))
    items = _get(data, path)
    how = draw(st.sampled_from(["empty", "first", "drop last", "repeat last"]))
    new = [] if how == "empty" else items[:1] if how == "first" else items[:-1] if how == "drop last" else None
    _set(data, path, new if new is not None else [*items, copy.deepcopy(items[-1])] if items else [])


GENERIC = [m_replace, m_number, m_delete, m_unknown_key, m_tag, m_list]


# --- geometry -------------------------------------------------------------------------------------------

_SQUARE = [[0.1, 0.1], [0.9, 0.1], [0.9, 0.9], [0.1, 0.9]]
unit = st.floats(-0.5, 1.5, allow_nan=False)
points = st.tuples(unit, unit).map(list)


@st.composite
def bad_polygons(draw) -> list[list[float]]:
    """Vertices in the unit square's frame: too few, repeated, collinear, clockwise, self-intersecting, ..."""
    kind = draw(
        st.sampled_from(
            ["few", "repeated", "same", "collinear", "clockwise", "bowtie", "spike", "pinched", "twice", "sliver",
             "tiny", "special", "random", "square"]
        )
    )  # fmt: skip
    if kind == "few":
        return draw(st.lists(points, max_size=2))
    if kind == "repeated":
        i = draw(st.integers(0, 3))
        return [*_SQUARE[: i + 1], _SQUARE[i], *_SQUARE[i + 1 :]]
    if kind == "same":
        return [draw(points)] * draw(st.integers(3, 5))
    if kind == "collinear":
        a, b = draw(points), draw(points)
        ts = draw(st.lists(st.floats(0, 1), min_size=3, max_size=6))
        return [[a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])] for t in ts]
    if kind == "clockwise":
        return _SQUARE[::-1]
    if kind == "bowtie":
        return [[0.1, 0.1], [0.9, 0.9], [0.9, 0.1], [0.1, 0.9]]
    if kind == "spike":  # a zero-width antenna: an edge runs back along the one before it
        return [[0.1, 0.1], [0.9, 0.1], [0.9, 0.9], [0.5, 0.9], [0.5, 1.3], [0.5, 0.9], [0.1, 0.9]]
    if kind == "pinched":  # two triangles touching at one vertex
        return [[0.1, 0.1], [0.5, 0.5], [0.9, 0.1], [0.9, 0.9], [0.5, 0.5], [0.1, 0.9]]
    if kind == "twice":  # the square traced round twice
        return _SQUARE + _SQUARE
    if kind == "sliver":
        return [[0.1, 0.5], [0.9, 0.5], [0.5, 0.5 + draw(st.sampled_from([1e-15, 1e-9, 1e-300, 0.0]))]]
    if kind == "tiny":
        s = draw(st.sampled_from([1e-12, 1e-300, 1e-6]))
        return [[0.5, 0.5], [0.5 + s, 0.5], [0.5 + s, 0.5 + s], [0.5, 0.5 + s]]
    if kind == "special":
        poly = copy.deepcopy(_SQUARE)
        poly[draw(st.integers(0, 3))][draw(st.integers(0, 1))] = draw(st.sampled_from(SPECIAL_NUMBERS))
        return poly
    if kind == "random":
        return draw(st.lists(points, min_size=3, max_size=10))
    return copy.deepcopy(_SQUARE)


def _domain(data: dict) -> tuple[float, float]:
    d = data.get("grid", {}).get("domain") if isinstance(data.get("grid"), dict) else None
    ok = isinstance(d, list) and len(d) == 2 and all(_is_number(x) and 0 < x < 1e3 for x in d)
    return (float(d[0]), float(d[1])) if ok else (1.0, 1.0)


def _in_domain(data: dict, poly: list) -> list:
    lx, ly = _domain(data)
    return [[x * lx, y * ly] for x, y in poly]


def _body_index(draw, data: dict) -> int:
    return draw(st.integers(0, len(data["bodies"]) - 1))


def g_wall_polygon(draw, data: dict) -> None:
    """A polygon wall gets degenerate vertices."""
    walls = data.setdefault("walls", [])
    polys = [i for i, w in enumerate(walls) if w.get("type") == "polygon"]
    vertices = _in_domain(data, draw(bad_polygons()))  # new lists
    if polys:
        walls[draw(st.sampled_from(polys))]["vertices"] = vertices
    else:
        walls.append({"type": "polygon", "vertices": vertices})


def g_body_polygon(draw, data: dict) -> None:
    """A body becomes a polygon with degenerate vertices, any scale, anywhere."""
    body = data["bodies"][_body_index(draw, data)]
    for k in ("min", "max", "radius", "center", "scale"):
        body.pop(k, None)
    body["shape"] = "polygon"
    body["vertices"] = [[x - 0.5, y - 0.5] for x, y in draw(bad_polygons())]
    lx, ly = _domain(data)
    body["scale"] = draw(st.sampled_from([0.3 * min(lx, ly), 1.0, 1e-9, 1e-300, 1e300, 0.0, -0.3]))
    body["center"] = draw(st.sampled_from([[0.5 * lx, 0.5 * ly], [0.0, 0.0], [lx, ly], [1e300, 0.5]]))


def _offset(draw, data: dict) -> tuple[float, float]:
    lx, ly = _domain(data)
    fixed = [(0.0, 0.0), (-0.3 * lx, 0.0), (0.0, -0.45 * ly), (0.45 * lx, 0.0), (2 * lx, 0.0), (1e3, 1e3), (1e300, 0)]
    return draw(st.sampled_from(fixed) | st.tuples(st.floats(-1.5 * lx, 1.5 * lx), st.floats(-1.5 * ly, 1.5 * ly)))


def g_body_move(draw, data: dict) -> None:
    """A body moves partly or fully outside the walls, or outside the domain."""
    body = data["bodies"][_body_index(draw, data)]
    dx, dy = _offset(draw, data)
    for k in ("min", "max", "center"):
        if k in body:
            body[k] = [body[k][0] + dx, body[k][1] + dy]


def g_body_size(draw, data: dict) -> None:
    """A body gets zero, negative, tiny (smaller than one particle) or huge size."""
    body = data["bodies"][_body_index(draw, data)]
    sizes = [0.0, -0.1, 1e-300, 1e-12, 1e-3, 0.01, 0.3, 10.0, 1e300, math.inf]
    if body["shape"] == "box":
        w, h = draw(st.sampled_from(sizes)), draw(st.sampled_from(sizes))
        body["max"] = [body["min"][0] + w, body["min"][1] + h]
    elif body["shape"] == "circle":
        body["radius"] = draw(st.sampled_from(sizes))
    else:
        body["scale"] = draw(st.sampled_from(sizes))


def g_walls_enclose_nothing(draw, data: dict) -> None:
    """The walls leave no room: a circle smaller than a cell, disjoint containers, an obstacle over everything."""
    lx, ly = _domain(data)
    c = [0.5 * lx, 0.5 * ly]
    options = [
        [{"type": "circle", "center": c, "radius": 1e-3, "side": "inside"}],
        [{"type": "circle", "center": c, "radius": 0.75 * max(lx, ly), "side": "outside"}],
        [
            {"type": "polygon", "vertices": _in_domain(data, [[0.05, 0.05], [0.45, 0.05], [0.45, 0.95], [0.05, 0.95]])},
            {"type": "polygon", "vertices": _in_domain(data, [[0.55, 0.05], [0.95, 0.05], [0.95, 0.95], [0.55, 0.95]])},
        ],
        [{"type": "polygon", "vertices": _in_domain(data, [[1.2, 0.1], [1.8, 0.1], [1.8, 0.9], [1.2, 0.9]])}],
        [{"type": "circle", "center": [-0.5 * lx, c[1]], "radius": 0.4 * lx, "side": "inside"}],
        [
            {"type": "polygon", "vertices": _in_domain(data, _SQUARE)},
            {"type": "circle", "center": c, "radius": 0.6 * max(lx, ly), "side": "outside"},
        ],
        [],
    ]
    data["walls"] = draw(st.sampled_from(options))


def g_circle_wall(draw, data: dict) -> None:
    """A circle wall gets radius 0, tiny, huge or non-finite, a centre anywhere, either side."""
    lx, ly = _domain(data)
    radius = draw(st.sampled_from([0.0, -1.0, 1e-300, 1e-9, 0.01, 0.5 * lx, lx, 10.0, 1e12, 1e300, math.inf]))
    center = draw(st.sampled_from([[0.5 * lx, 0.5 * ly], [0.0, 0.0], [-lx, ly], [1e300, 0.0], [math.nan, 0.5]]))
    wall = {"type": "circle", "center": center, "radius": radius, "side": draw(st.sampled_from(["inside", "outside"]))}
    walls = data.setdefault("walls", [])
    circles = [i for i, w in enumerate(walls) if w.get("type") == "circle"]
    if circles and draw(st.booleans()):
        walls[draw(st.sampled_from(circles))] = wall
    else:
        walls.append(wall)


def g_seeding(draw, data: dict) -> None:
    """A body's seeding becomes very sparse, dense, zero, both kinds or neither."""
    body = data["bodies"][_body_index(draw, data)]
    spacing = st.sampled_from([0.0, -0.01, 1e-300, 1e-7, 1e-3, 0.05, 1.0, 1e300, math.inf])
    per_cell = st.sampled_from([0, 1, 2, 9, 1024, 1025, 2**32, -1])
    body["seeding"] = draw(
        st.sampled_from([{}])
        | st.fixed_dictionaries({"spacing": spacing})
        | st.fixed_dictionaries({"per_cell": per_cell})
        | st.fixed_dictionaries({"spacing": spacing, "per_cell": per_cell})
    )


DOMAINS = [
    [1.0, 1.0], [1.0, 0.5], [1.0, 1 / 3], [1e-6, 1e-6], [1e6, 1e6], [1.0, 1e-300], [3.0, 1.5], [5e-324, 1.0],
    [1e-300, 1e300], [1.0, 1e300],
]  # fmt: skip


def g_grid(draw, data: dict) -> None:
    """The grid gets few or many cells and a tiny, huge, subnormal or fractional domain."""
    grid = data["grid"]
    grid["resolution"] = draw(st.sampled_from([2, 3, 4, 5, 7, 16, 33, 100, 1000, 65536, 65537]))
    if draw(st.booleans()):
        grid["domain"] = copy.deepcopy(draw(st.sampled_from(DOMAINS)))


GEOMETRY = [
    g_wall_polygon, g_body_polygon, g_body_move, g_body_size, g_walls_enclose_nothing, g_circle_wall, g_seeding,
    g_grid,
]  # fmt: skip


@st.composite
def mutated_scenes(draw, mutations: list, most: int = 3) -> dict:
    """A base scene with one to ``most`` mutations drawn from ``mutations``, applied in turn."""
    data = copy.deepcopy(BASES[draw(st.sampled_from(sorted(BASES)))])
    for _ in range(draw(st.integers(1, most))):
        mutate = draw(st.sampled_from(mutations))
        try:
            mutate(draw, data)
        except (KeyError, IndexError, TypeError, ValueError, AttributeError):
            pass  # an earlier mutation removed what this one edits: the scene is mutated enough
    return data


#: Keys of geometry, grid size and seeding, left alone by :func:`perturbed_scenes`.
_SHAPE_KEYS = {"vertices", "min", "max", "center", "radius", "scale", "domain", "resolution", "seeding", "seed"}


@st.composite
def perturbed_scenes(draw) -> dict:
    """A base scene in either precision with up to four physical numbers (materials, gravity, velocities, time
    step, wall speeds, augmented-grid settings) scaled by up to 10^±300 or negated: often valid and extreme."""
    data = copy.deepcopy(BASES[draw(st.sampled_from(sorted(BASES)))])
    data["precision"] = draw(st.sampled_from(["f64", "f32"]))  # f32: finite inputs may overflow in the engine
    paths = [p for p in _paths(data) if _is_number(_get(data, p)) and not _SHAPE_KEYS.intersection(map(str, p))]
    factors = st.sampled_from([-1.0, 0.0, 1e-300, 1e-12, 1e-6, 1e-3, 0.1, 3.0, 1e3, 1e6, 1e12, 1e38, 1e300])
    for path in draw(st.permutations(paths))[: draw(st.integers(1, 4))]:
        value = _get(data, path)
        if isinstance(value, float):  # a zero (a still wall, no gravity along x) is scaled from 1
            _set(data, path, (value or 1.0) * draw(factors))
        elif path[-1] != "steps":
            _set(data, path, max(1, value * int(draw(st.sampled_from([1, 2, 10, 2**20])))))
    return data


# --- one case -------------------------------------------------------------------------------------------


def _schema_keys(model: type[BaseModel], seen: set | None = None) -> set[str]:
    """Every field name of the scene schema, nested models included."""
    seen = set() if seen is None else seen
    names = set()

    def walk(tp: object) -> None:
        if isinstance(tp, type) and issubclass(tp, BaseModel) and tp not in seen:
            seen.add(tp)
            names.update(_schema_keys(tp, seen))
        for arg in typing.get_args(tp):
            walk(arg)

    for name, field in model.model_fields.items():
        names.add(name)
        walk(field.annotation)
    return names


SCHEMA_KEYS = _schema_keys(Scene) | _schema_keys(Scene3)


def _names_a_key(key: str, data: dict) -> bool:
    """Whether ``key`` ("bodies[1].material.density") walks the scene: indices in range, names in the file or schema."""
    tokens = re.findall(r"\[(\d+)\]|\.?([^.\[\]]+)", key)
    if not tokens or "".join(f"[{i}]" if i else f".{n}" for i, n in tokens).lstrip(".") != key:
        return False
    node: object = data
    for index, name in tokens:
        if index:
            if not (isinstance(node, list) and int(index) < len(node)):
                return False
            node = node[int(index)]
        else:
            if not (name in SCHEMA_KEYS or (isinstance(node, dict) and name in node)):
                return False
            node = node.get(name) if isinstance(node, dict) else None
    return True


def _key_problem(err: BaseException, data: dict, where: str) -> str:
    key = getattr(err, "key", None)
    if not isinstance(key, str) or not key:
        return f"{where}: SceneError without a key: {err!r}"
    if not str(err).startswith(f"{key}: "):
        return f"{where}: SceneError message does not start with its key {key!r}: {err}"
    if not _names_a_key(key, data):
        return f"{where}: SceneError key {key!r} names no key of the scene: {err}"
    return ""


def _differs(given: object, loaded: object, key: str = "") -> str:
    """Where the loaded scene differs from the file (a value coerced from another type, a key dropped)."""
    if isinstance(given, dict):
        if not isinstance(loaded, dict):
            return key
        for k, v in given.items():
            sub = f"{key}.{k}" if key else k
            if v is None and k not in loaded:
                continue  # None is "not given" for an optional key, and the dump leaves it out
            if k not in loaded or (d := _differs(v, loaded[k], sub)):
                return sub if k not in loaded else d
        return ""
    if isinstance(given, list):
        if not isinstance(loaded, list) or len(given) != len(loaded):
            return key
        return next(
            (d for i, (g, v) in enumerate(zip(given, loaded, strict=True)) if (d := _differs(g, v, f"{key}[{i}]"))), ""
        )
    if _is_number(given):
        return "" if _is_number(loaded) and float(given) == float(loaded) else key
    return "" if type(given) is type(loaded) and given == loaded else key


def _cost(scene: Scene | Scene3) -> tuple[float, float]:
    """Grid nodes and the largest body's seeding candidates, as the engine counts them (before refusing)."""
    g = scene.grid
    h = g.cell_size
    dim = len(g.domain)
    with np.errstate(all="ignore"):
        nodes = float(np.prod([g.resolution + 5] + [round(g.domain[k] / h) + 5 for k in range(1, dim)]))
    worst = 0.0
    for body in scene.bodies:
        s = body.seeding
        spacing = s.spacing or (h / s.per_cell ** (1 / dim) if s.per_cell else h / 2)
        if body.shape == "box":
            size = [body.max[k] - body.min[k] for k in range(dim)]
        elif body.shape in ("circle", "sphere"):
            size = [2 * body.radius] * dim
        elif body.shape == "cylinder":
            size = [2 * body.radius + body.length] * dim
        else:
            size = [
                body.scale * (max(v[k] for v in body.vertices) - min(v[k] for v in body.vertices)) for k in range(2)
            ]
        with np.errstate(all="ignore"):
            worst = max(worst, float(np.prod([np.ceil(np.float64(x) / spacing) + 1 for x in size])))
    return nodes, worst


def _non_finite(sim: augmpm.Simulation) -> str:
    """The parts of the state (and of what a run reports) that are not finite, or ""."""
    state = {
        "positions": sim.positions,
        "velocities": sim.velocities,
        "densities": sim.densities,
        "kinetic_energy": sim.metrics()["kinetic_energy"],
        "time": sim.time,
        "dt": sim.dt,
    }
    return ", ".join(name for name, a in state.items() if not np.isfinite(a).all())


def run_case(data: dict, workdir: Path, as_toml: bool = True) -> tuple[list[str], str]:
    """Loads (from a TOML file, or with ``Scene.from_dict`` for what TOML cannot hold), builds with both methods
    and steps one scene; returns what went wrong and a label of the outcome."""
    load = "load_scene" if as_toml else "Scene.from_dict"
    try:
        if as_toml:
            path = workdir / "case.toml"
            path.write_text(tomli_w.dumps(data), encoding="utf-8")
            scene = augmpm.load_scene(path)
        else:
            scene = scene_class(data).from_dict(data)
    except augmpm.SceneError as e:
        return [p for p in [_key_problem(e, data, load)] if p], f"refused at load: {e.key}"
    if where := _differs(data, scene.to_dict()):
        return [f"{load} accepted {where} but the scene it returned has another value there"], "coerced"
    nodes, candidates = _cost(scene)
    if BUDGET_NODES < nodes <= ENGINE_MAX_NODES or BUDGET_CANDIDATES < candidates <= ENGINE_MAX_CANDIDATES:
        return [], "valid but large: loaded only"
    problems, labels = [], []
    for method in ("naive", "augmented"):
        try:
            sim = augmpm.Simulation(scene, method=method, threads=1)
        except augmpm.SceneError as e:
            problems.append(_key_problem(e, data, f"Simulation({method})"))
            labels.append(f"refused at build: {e.key}")
            continue
        if sim.num_particles < 1:
            problems.append(f"Simulation({method}) built with no particle")
        if bad := _non_finite(sim):
            problems.append(f"Simulation({method}): {bad} non-finite before any step")
        try:
            sim.step(STEPS)
        except augmpm.SimulationError as e:
            step, particle = getattr(e, "step", None), getattr(e, "particle", None)
            if not (type(step) is int and 1 <= step <= STEPS and type(particle) is int):
                problems.append(f"step({method}): SimulationError with step={step!r}, particle={particle!r}: {e}")
            elif not 0 <= particle < sim.num_particles:
                problems.append(f"step({method}): SimulationError names particle {particle} of {sim.num_particles}")
            labels.append("failed run")
            continue
        if bad := _non_finite(sim):
            problems.append(f"step({method}): {bad} went non-finite without a SimulationError")
        labels.append("ran")
    return [p for p in problems if p], " / ".join(labels)


# --- the worker process ---------------------------------------------------------------------------------


def _serve() -> None:
    """Worker loop: one JSON line in (the scene, as TOML), one JSON line out (problems, label)."""
    proto = os.fdopen(os.dup(1), "w", buffering=1)
    log = open(sys.argv[2], "ab", buffering=0)
    os.dup2(log.fileno(), 1)
    os.dup2(log.fileno(), 2)
    sys.stdout = sys.stderr = open(log.fileno(), "w", buffering=1, closefd=False)
    import resource

    with open("/proc/self/statm") as fh:
        held = int(fh.read().split()[0]) * resource.getpagesize()
    resource.setrlimit(resource.RLIMIT_AS, (held + WORKER_EXTRA_BYTES, resource.RLIM_INFINITY))
    workdir = Path(tempfile.mkdtemp(prefix="cases-", dir=Path(sys.argv[2]).parent))
    proto.write("ready\n")
    while line := sys.stdin.readline():
        case = json.loads(line)
        as_toml = "toml" in case
        data = tomllib.loads(case["toml"]) if as_toml else json.loads(case["json"])
        start = log.tell()
        try:
            problems, label = run_case(data, workdir, as_toml)
        except BaseException:  # a pyo3 PanicException derives from BaseException
            problems, label = [f"unexpected exception:\n{traceback.format_exc()}"], "bug"
        sys.stderr.flush()
        with open(sys.argv[2], "rb") as fh:
            fh.seek(start)
            printed = fh.read().decode(errors="replace")
        if "panicked" in printed or "Traceback" in printed:
            problems.append(f"printed to stderr:\n{printed[-3000:]}")
        proto.write(json.dumps({"problems": problems, "label": label}) + "\n")


class _Worker:
    """A process running cases one at a time; restarted after a crash or a hang."""

    def __init__(self, logdir: Path) -> None:
        self.logdir, self.proc, self.count = logdir, None, 0

    def _start(self) -> None:
        self.count += 1
        self.log = self.logdir / f"worker-{self.count}.log"
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "tests.test_fuzz", "--worker", str(self.log)],
            cwd=ROOT,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            env={**os.environ, "AUGMPM_THREADS": "1", "RAYON_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"},
        )
        if self._reply(60.0) != "ready":
            raise RuntimeError(f"the fuzz worker did not start:\n{self._tail()}")

    def _reply(self, timeout: float) -> str | None:
        """The worker's next line; "" if it exited, None if it sends nothing within ``timeout`` seconds."""
        with selectors.DefaultSelector() as sel:
            sel.register(self.proc.stdout, selectors.EVENT_READ)
            return self.proc.stdout.readline().strip() if sel.select(timeout) else None

    def _tail(self) -> str:
        return self.log.read_text(errors="replace")[-3000:] if self.log.exists() else ""

    def stop(self) -> None:
        if self.proc is not None:
            self.proc.kill()
            self.proc.wait()
            self.proc = None

    def run(self, case: dict[str, str]) -> tuple[list[str], str]:
        """Runs ``{"toml": text}`` or ``{"json": text}`` (a scene TOML cannot hold); returns problems and a label."""
        if self.proc is None or self.proc.poll() is not None:
            self._start()
        self.proc.stdin.write(json.dumps(case) + "\n")
        self.proc.stdin.flush()
        line = self._reply(CASE_LIMIT_S)
        if line:
            reply = json.loads(line)
            return reply["problems"], reply["label"]
        if line is None:
            self.stop()
            return [f"hang: no outcome within {CASE_LIMIT_S} s\n{self._tail()}"], "bug"
        status = self.proc.wait()  # negative: killed by that signal (an abort, a segfault, the memory limit)
        self.stop()
        return [f"the worker died (exit status {status})\n{self._tail()}"], "bug"


@pytest.fixture(scope="module")
def worker(tmp_path_factory):
    w = _Worker(tmp_path_factory.mktemp("fuzz-workers"))
    yield w
    w.stop()


def _inline(value: object) -> str:
    if isinstance(value, dict):
        return "{" + ", ".join(f"{_key(k)} = {_inline(v)}" for k, v in value.items()) + "}"
    if isinstance(value, list):
        return "[" + ", ".join(map(_inline, value)) + "]"
    return tomli_w.dumps({"v": value})[len("v = ") :].strip()  # a scalar as tomli_w spells it


def _key(key: str) -> str:
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else json.dumps(key)


def _canonical(data: dict) -> str:
    return json.dumps(data, sort_keys=True, default=repr)


def _compact_toml(data: dict) -> str:
    """``data`` as TOML with one line per key (tables and arrays of tables as sections): a readable reproducer."""
    lines, sections = [], []
    for k, v in data.items():
        if isinstance(v, dict) and v:
            sections += [f"\n[{_key(k)}]", *(f"{_key(a)} = {_inline(b)}" for a, b in v.items())]
        elif isinstance(v, list) and v and all(isinstance(x, dict) and x for x in v):
            for item in v:
                sections += [f"\n[[{_key(k)}]]", *(f"{_key(a)} = {_inline(b)}" for a, b in item.items())]
        else:
            lines.append(f"{_key(k)} = {_inline(v)}")
    return "\n".join(lines + sections) + "\n"


def check(worker: _Worker, data: dict) -> None:
    try:
        case = {"toml": tomli_w.dumps(data)}
        short = _compact_toml(data)
        same = _canonical(tomllib.loads(short)) == _canonical(tomllib.loads(case["toml"]))
        shown = f"--- scene.toml ---\n{short if same else case['toml']}"
    except TypeError:  # None: only Python callers can pass it, through Scene.from_dict
        case = {"json": json.dumps(data, default=str)}
        shown = f"--- Scene.from_dict({data!r}) ---"
    started = time.monotonic()
    problems, label = worker.run(case)
    if currently_in_test_context():  # the outcome counts, for --hypothesis-show-statistics
        event(label.split(": ")[0] if label.startswith("refused") else label)
    if problems:
        pytest.fail("\n".join(problems) + f"\n({time.monotonic() - started:.1f} s)\n{shown}", pytrace=False)


# --- the properties -------------------------------------------------------------------------------------


def _small_with(path: Path_, value: object) -> dict:
    data = copy.deepcopy(_SMALL)
    _set(data, path, value)
    return data


#: Scenes the fuzzer found mishandled by scene.py, each run first in every suite run.
REGRESSIONS = [
    # Passed validation, then the engine's JSON parser refused it under the key "scene" (u64 overflow).
    _small_with(("time", "steps"), 2**64),
    _small_with(("time", "output_interval"), 2**64),
    # A short vector named an item the file does not have ("gravity[1]: required key is missing").
    _small_with(("gravity",), [1.0]),
    # Strings and booleans were converted to numbers ("1.5" -> 1.5, true -> 1.0), integers to booleans.
    _small_with(("gravity",), ["1.5", 0.0]),
    _small_with(("gravity",), [True, 0.0]),
    _small_with(("grid", "resolution"), "16"),
    _small_with(("seed",), True),
    _small_with(("grid", "density_wall_correction"), 1),
    _small_with(("grid", "density_wall_correction"), "yes"),
    # ZeroDivisionError (a subnormal width gives h = 0) and OverflowError (round(inf)) escaped the validator.
    _small_with(("grid", "domain"), [5e-324, 1.0]),
    _small_with(("grid", "domain"), [1e-300, 1e300]),
]


def _with_regressions(test):
    for data in REGRESSIONS:
        test = example(data=data)(test)
    return test


@_fuzz_settings(suite_examples=300)
@given(data=mutated_scenes(GENERIC))
@_with_regressions
def test_mutated_scene_runs_or_names_its_key(worker, data):
    """Wrong types, missing or unknown keys and extreme numbers end in a finite run or a keyed SceneError."""
    check(worker, data)


@_fuzz_settings(suite_examples=250)
@given(data=mutated_scenes([*GEOMETRY, m_number], most=2))
def test_bad_geometry_runs_or_names_its_key(worker, data):
    """Degenerate polygons, misplaced bodies and empty walls end in a finite run or a keyed SceneError."""
    check(worker, data)


@_fuzz_settings(suite_examples=150)
@given(data=perturbed_scenes())
def test_extreme_valid_scene_runs_finite_or_says_so(worker, data):
    """Scenes with numbers scaled far from the base run finite, fail with SimulationError, or are refused by key."""
    check(worker, data)


#: Scenes on which the fuzzer caught the engine (crates/), kept as regressions.
ENGINE_BUGS = {
    # Particles::kinetic_energy summed m * |v|^2: |v|^2 = 1e320 overflowed although 1/2 m |v|^2 (4.5e118) does not.
    # Now summed as (sqrt(m) |v|)^2 in f64.
    "kinetic energy overflows in |v|^2": {
        **_SMALL,
        "bodies": [
            {
                **_SMALL["bodies"][0],
                "velocity": [1e160, 0.0],
                "material": {**_SMALL["bodies"][0]["material"], "density": 1e-200},
            }
        ],
    },
    # A wall surface speed of 1e300 m/s with a tiny dt: the state stayed finite (|v| ~ 5e298 near the wall, augmented
    # method) but its kinetic energy was beyond every float and no error was raised. Now a particle whose kinetic
    # energy leaves the f64 range fails the step (SimulationError), like a non-finite one.
    "kinetic energy beyond every float": {
        **_SMALL,
        "time": {**_SMALL["time"], "dt": 1e-300},
        "walls": [{**_SMALL["walls"][0], "tangential_speed": 1e300}],
        "bodies": [{**_SMALL["bodies"][0], "min": [0.3, 0.3], "max": [0.6, 0.6]}],
    },
}


@pytest.mark.parametrize("name", sorted(ENGINE_BUGS))
def test_engine_bug_found_by_fuzzing(worker, name):
    """A scene on which the fuzzer caught the engine runs finite, fails with SimulationError or is refused by key."""
    check(worker, copy.deepcopy(ENGINE_BUGS[name]))


#: A handful of bad scenes for the command line (each case is a subprocess): (table, key, value, key named).
CLI_CASES = {
    "unknown key": (("grid",), "resolutoin", 16, "grid.resolutoin"),
    "NaN gravity": ((), "gravity", [math.nan, 0.0], "gravity[0]"),
    "bow-tie wall": (("walls", 0), "vertices", [[0.1, 0.1], [0.9, 0.9], [0.9, 0.1], [0.1, 0.9]], "walls[0].vertices"),
    "body outside the walls": (("bodies", 0), "min", [-0.5, 0.5], "bodies[0]"),
    "walls enclose nothing": ((), "walls", [{"type": "circle", "center": [0.5, 0.5], "radius": 0.75}], "bodies[0]"),
    "subnormal domain width": (("grid",), "domain", [5e-324, 1.0], "grid.domain"),  # was a ZeroDivisionError traceback
}


@pytest.mark.parametrize("case", sorted(CLI_CASES))
def test_bad_scene_cli_exits_with_one_line(tmp_path, case):
    """`augmpm run` on a bad scene exits 2 with one line naming the key: no traceback, no panic."""
    table, key, value, named = CLI_CASES[case]
    data = copy.deepcopy(_SMALL)
    _get(data, table)[key] = value
    scene = tmp_path / "bad.toml"
    scene.write_text(tomli_w.dumps(data), encoding="utf-8")
    args = ["run", str(scene), "--out", str(tmp_path / "out"), "--steps", "2", "--no-render", "--no-progress"]
    proc = subprocess.run(
        [sys.executable, "-m", "augmpm", *args, "--threads", "1"], capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr and "panicked" not in proc.stderr, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"augmpm: bad input: {named}: "), proc.stderr


def test_blown_up_run_cli_exits_1(tmp_path):
    """`augmpm run` of a scene that goes non-finite exits 1 saying where, without a traceback."""
    data = copy.deepcopy(_SMALL)
    data["time"]["dt"] = 1e3
    scene = tmp_path / "blowup.toml"
    scene.write_text(tomli_w.dumps(data), encoding="utf-8")
    args = ["run", str(scene), "--out", str(tmp_path / "out"), "--steps", "5", "--no-render", "--no-progress"]
    proc = subprocess.run([sys.executable, "-m", "augmpm", *args], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 1, proc.stderr
    assert "Traceback" not in proc.stderr and "panicked" not in proc.stderr, proc.stderr
    assert "run failed" in proc.stderr


if __name__ == "__main__" and sys.argv[1:2] == ["--worker"]:
    _serve()
