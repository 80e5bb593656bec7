"""Scene files: TOML in, a validated :class:`Scene` out.

Every key is declared once, in the engine's types, which export a JSON Schema (:data:`SCHEMA`); the
pydantic models here are built from it and check types, unknown keys and ranges, naming the key of
every error. The rules between keys (one of ``time.dt`` and ``time.cfl``, ...) are the engine's,
asked of it when a scene is validated; geometry (polygon orientation and self-intersection, bodies
inside the walls) is checked when the simulation is built.
"""

from __future__ import annotations

import difflib
import functools
import json
import math
import tomllib
import typing
from pathlib import Path
from typing import Annotated, Any, Literal

import meshio
import numpy as np
import pydantic
import tomli_w
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, PlainSerializer, ValidationError, model_validator
from pydantic_core import PydanticCustomError

from augmpm import _core
from augmpm._core import SceneError


def _typed(expected: str) -> BeforeValidator:
    """Refuses a string or a boolean where a number belongs: TOML is typed, so "1.5" or true there is a
    mistake to report, not a value to convert (pydantic's lax mode would read them as 1.5 and 1)."""

    def check(value: Any) -> Any:
        if isinstance(value, str | bool):
            kind = "a boolean" if isinstance(value, bool) else "a string"
            raise PydanticCustomError("type", f"Input should be a valid {expected}, not {kind}")
        return value

    return BeforeValidator(check)


_NUMBER, _INTEGER = _typed("number"), _typed("integer")

#: The JSON Schema of scene files, exported by the engine from the types that declare every key once
#: (name, type, default, range, unit, doc line). The models below are built from it.
SCHEMA: dict[str, Any] = json.loads(_core.scene_schema())
#: The JSON Schema of 3D scene files (``grid.domain`` with three components): the same keys with
#: three-component vectors, and the 3D walls and bodies.
SCHEMA3: dict[str, Any] = json.loads(_core.scene3_schema())
# One table of types for both: the types they share are the same.
_DEFS: dict[str, Any] = {**SCHEMA3["$defs"], **SCHEMA["$defs"]}


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_assignment=True)

    # Changed in code, a scene reports a bad value as loading one does: SceneError, naming the key.
    def __setattr__(self, name: str, value: Any) -> None:
        try:
            super().__setattr__(name, value)
        except ValidationError as e:
            raise _scene_error(e) from None


# What the Python models add to the schema's keys, by the schema's type name.


class _Grid(_Strict):
    @property
    def cell_size(self) -> float:
        """Cell width h (m)."""
        return self.domain[0] / self.resolution


class _Time(_Strict):
    def total_steps(self, dt: float) -> int:
        """The steps of the whole run at time step ``dt`` (s): ``steps``, or ⌈end / dt⌉ (an end within
        rounding of a whole number of steps takes that number)."""
        if self.steps is not None:
            return self.steps
        n = self.end / dt
        whole = round(n)
        total = whole if abs(n - whole) <= 1e-9 * max(whole, 1) else math.ceil(n)
        if total >= 2**63:
            raise _plain_error("time.end", f"{self.end} s at dt = {dt} s is more than 2**63 steps")
        return total


class _Scene(_Strict):
    """A whole scene. Build one in code with keyword arguments or :meth:`from_dict`."""

    # Built in code, a scene reports a bad value as loading one does: SceneError, naming the dotted key.
    # (Only here: pydantic calls an overridden __init__ of nested models too, which would lose the path.)
    def __init__(self, **data: Any) -> None:
        try:
            super().__init__(**data)
        except ValidationError as e:
            raise _scene_error(e) from None

    # The rules between keys (one of dt and cfl, whole cells, ...) are the engine's, checked where it
    # checks them: each key's own range is checked above, by the fields built from the schema.
    @model_validator(mode="after")
    def _rules(self) -> Any:
        _core.check_scene(self.to_json())
        return self

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Any:
        """Validates a plain dict (as read from TOML); raises :class:`SceneError` naming the key."""
        try:
            return cls.model_validate(data)
        except ValidationError as e:
            raise _scene_error(e) from None

    def to_dict(self) -> dict[str, Any]:
        return self.model_dump(mode="json", exclude_none=True)

    def to_json(self) -> str:
        """The scene as the engine takes it: every mesh ``file`` read into ``vertices`` and ``triangles``."""
        return json.dumps(_with_meshes_read(self.to_dict()))

    def to_toml(self) -> str:
        return tomli_w.dumps(self.to_dict())

    def with_overrides(self, overrides: list[str]) -> Any:
        """A copy with ``key=value`` overrides applied (see :func:`apply_override`)."""
        data = self.to_dict()
        for item in overrides:
            apply_override(data, item)
        return type(self).from_dict(data)


_BASES: dict[str, type[_Strict]] = {
    "Scene": _Scene,
    "Scene3": _Scene,
    "GridSpec": _Grid,
    "Grid3Spec": _Grid,
    "TimeSpec": _Time,
}


def _python_name(name: str) -> str:
    """The Python name of a schema type: ``GridSpec`` → ``Grid``."""
    return name.removesuffix("Spec")


def _def_of(schema: dict[str, Any]) -> tuple[str, dict[str, Any]] | None:
    ref = schema.get("$ref")
    return (ref.rsplit("/", 1)[-1], _DEFS[ref.rsplit("/", 1)[-1]]) if ref else None


def _tag_of(options: list[dict[str, Any]]) -> str | None:
    """The key that tells the options of a choice of tables apart (``type``, ``shape``)."""
    props = options[0].get("properties", {})
    for name, prop in props.items():
        if "const" in prop and all("const" in o.get("properties", {}).get(name, {}) for o in options):
            return name
    return None


def _bounds(schema: dict[str, Any]) -> dict[str, Any]:
    names = {"minimum": "ge", "maximum": "le", "exclusiveMinimum": "gt", "exclusiveMaximum": "lt"}
    return {arg: schema[key] for key, arg in names.items() if key in schema}


def _number_or_infinity(number: dict[str, Any]) -> Any:
    """A number in the bounds of `number`, or infinity: written "inf" in JSON (which has no infinity)
    and in files, where TOML's own `inf` is read too. In Python it is a float (`math.inf`)."""

    def read(value: Any) -> Any:
        if isinstance(value, str) and value.lower() == "inf":
            return math.inf
        if isinstance(value, str | bool) or (isinstance(value, float) and math.isnan(value)):
            raise PydanticCustomError("type", 'Input should be a number or "inf"')
        return value

    def write(value: float) -> Any:
        return "inf" if value == math.inf else value

    return Annotated[
        float,
        Field(allow_inf_nan=True, **_bounds(number)),
        BeforeValidator(read),
        PlainSerializer(write, when_used="json"),
    ]


def _annotation(schema: dict[str, Any], hint: str) -> Any:
    """The pydantic type of a key's schema (its doc, default and unit go to its Field)."""
    if (found := _def_of(schema)) is not None:
        return _annotation(found[1], found[0])
    if "anyOf" in schema:  # any one of the options (an optional key: its type or null)
        options = [o for o in schema["anyOf"] if o.get("type") != "null"]
        if any(o.get("const") == "inf" for o in options):
            number = next(o for o in options if o.get("type") == "number")
            t = _number_or_infinity(number)
        else:
            t = _annotation(options[0], hint)
            for option in options[1:]:
                t = t | _annotation(option, hint)
        return t | None if len(options) < len(schema["anyOf"]) else t
    if "oneOf" in schema:
        options = schema["oneOf"]
        if all("const" in o for o in options):
            return Literal[tuple(o["const"] for o in options)]
        tag = _tag_of(options)
        models = tuple(_model(o["title"], o, shared=schema) for o in options)
        return Annotated[typing.Union[models], Field(discriminator=tag)]  # noqa: UP007 (a runtime tuple)
    kinds = schema.get("type")
    kinds = [kinds] if isinstance(kinds, str) else list(kinds or [])
    optional = "null" in kinds
    kind = next(k for k in kinds if k != "null")
    if kind == "object":
        t: Any = _model(hint, schema)
    elif kind == "number":
        t = Annotated[float, _NUMBER, Field(allow_inf_nan=False, **_bounds(schema))]
    elif kind == "integer":
        t = Annotated[int, _INTEGER, Field(**_bounds(schema))]
    elif kind == "boolean":
        t = Annotated[bool, Field(strict=True)]
    elif kind == "string":
        t = Literal[schema["const"]] if "const" in schema else str
    elif kind == "array":
        item = _annotation(schema["items"], hint)
        n = schema.get("minItems")
        if n is not None and n == schema.get("maxItems"):
            t = tuple[(item,) * n]
        else:
            t = Annotated[list[item], Field(min_length=n)] if n else list[item]
    else:
        raise TypeError(f"scene schema: no Python type for {kind!r} ({hint})")
    return t | None if optional else t


_MODELS: dict[str, type[_Strict]] = {}


def _model(name: str, schema: dict[str, Any], shared: dict[str, Any] | None = None) -> type[_Strict]:
    """The model of a table: its own keys, and those of ``shared``, the schema of a choice whose options
    add their keys to common ones (a body's shape beside its material)."""
    name = _python_name(name)
    if name in _MODELS:
        return _MODELS[name]
    properties = {**(shared or {}).get("properties", {}), **schema.get("properties", {})}
    required = {*(shared or {}).get("required", []), *schema.get("required", [])}
    fields: dict[str, Any] = {}
    for key, prop in properties.items():
        annotation = _annotation(prop, key)
        extra = {"unit": prop["unit"]} if "unit" in prop else None
        info: dict[str, Any] = {"description": prop.get("description"), "json_schema_extra": extra}
        if key not in required:
            default = prop.get("default")
            found = _def_of(prop)
            if isinstance(default, dict) and found is not None:
                model = _MODELS[_python_name(found[0])]
                info["default_factory"] = lambda model=model, default=default: model.model_validate(default)
            elif isinstance(default, list) and typing.get_origin(annotation) is tuple:
                info["default"] = tuple(default)
            elif isinstance(default, list):
                info["default_factory"] = lambda default=default: list(default)
            else:
                info["default"] = default
        fields[key] = (annotation, Field(**info))
    base = _BASES.get(name, _BASES.get(f"{name}Spec", _Strict))
    model = pydantic.create_model(name, __base__=base, __doc__=schema.get("description"), **fields)
    model.__module__ = __name__
    _MODELS[name] = model
    return model


Scene = _model("Scene", SCHEMA)
#: A 3D scene: the keys of :class:`Scene` with three-component vectors, and the 3D walls and bodies.
Scene3 = _model("Scene3", SCHEMA3)
Grid, Time, Augmented, Seeding = (_MODELS[n] for n in ("Grid", "Time", "Augmented", "Seeding"))
PolygonWall, CircleWall, PolylineWall = _MODELS["PolygonWall"], _MODELS["CircleWall"], _MODELS["PolylineWall"]
PolygonBody, BoxBody, CircleBody = _MODELS["PolygonBody"], _MODELS["BoxBody"], _MODELS["CircleBody"]
Fluid, Elastic, Stvk, Snow, Sand = (_MODELS[n] for n in ("Fluid", "Elastic", "Stvk", "Snow", "Sand"))
#: How walls act on the grid, by name.
Method = _annotation(_DEFS["Method"], "Method")
WallCondition = _annotation(_DEFS["WallCondition"], "WallCondition")


def _choice_tags() -> set[str]:
    """The names that choose an option of a table (``polygon``, ``fluid``): pydantic puts them in the path
    of an error inside the option, where the file has no such key."""
    tags: set[str] = set()
    for d in _DEFS.values():
        options = d.get("oneOf", [])
        tag = _tag_of(options) if options and not all("const" in o for o in options) else None
        if tag:
            tags.update(o["properties"][tag]["const"] for o in options)
    return tags


_TAGS = _choice_tags()


def _format_loc(loc: tuple[Any, ...]) -> str:
    key = ""
    for part in loc:
        if isinstance(part, int):
            key += f"[{part}]"
        elif part in _TAGS and key:
            continue  # the tag of a discriminated union, not a key of the file
        else:
            key += ("." if key else "") + str(part)
    return key or "scene"


def _scene_keys(root: type[BaseModel]) -> set[str]:
    """Every key a scene's tables can hold (the fields of all its models)."""
    keys: set[str] = set()
    pending: list[type[BaseModel]] = [root]
    seen: set[type[BaseModel]] = set()
    while pending:
        model = pending.pop()
        if model in seen:
            continue
        seen.add(model)
        keys.update(model.model_fields)
        for field in model.model_fields.values():
            for arg in _types_in(field.annotation):
                if isinstance(arg, type) and issubclass(arg, BaseModel):
                    pending.append(arg)
    return keys


def _keys_at(loc: tuple[Any, ...], root: type[BaseModel]) -> set[str]:
    """The keys of the table at ``loc`` (a pydantic error location, list indices and choice tags
    included), or an empty set when the path leads to no single table."""
    models: list[type[BaseModel]] = [root]
    for part in loc:
        if isinstance(part, int):
            continue
        if part in _TAGS:  # the option of a choice: keep the model whose tag it is
            models = [m for m in models if any(part in typing.get_args(f.annotation) for f in m.model_fields.values())]
            continue
        fields = [m.model_fields[part] for m in models if part in m.model_fields]
        types = [t for f in fields for t in _types_in(f.annotation)]
        models = [t for t in types if isinstance(t, type) and issubclass(t, BaseModel)]
    return set().union(*(m.model_fields for m in models))


def _types_in(annotation: Any) -> list[Any]:
    """The types an annotation names, through unions, lists, tuples and Annotated."""
    args = typing.get_args(annotation)
    if not args:
        return [annotation]
    return [annotation, *(t for a in args for t in _types_in(a))]


def _scene_error(e: ValidationError) -> SceneError:
    first = e.errors()[0]
    loc = tuple(first["loc"])
    key = _format_loc(loc)
    reason = first["msg"]
    if first["type"] == "extra_forbidden":
        reason = "unknown key"
        # The scene's own table: a 3D scene's keys for a 3D scene.
        root = Scene3 if e.title == "Scene3" else Scene
        keys = _keys_at(loc[:-1], root) or _scene_keys(root)
        keys -= {str(loc[-1])} if loc else set()
        guess = difflib.get_close_matches(str(loc[-1]), keys, n=1, cutoff=0.75) if loc else []
        if guess:
            reason += f" (did you mean {guess[0]!r}?)"
    elif first["type"] == "missing" and loc and isinstance(loc[-1], int):
        # A short vector, e.g. gravity = [1.0]: name the vector, not an item the file does not have.
        key, reason = _format_loc(loc[:-1]), f"too few items (item {loc[-1]} is missing)"
    elif first["type"] == "missing":
        reason = "required key is missing"
    more = len(e.errors()) - 1
    if more:
        reason += f" (and {more} more error{'s' if more > 1 else ''})"
    err = SceneError(f"{key}: {reason}")
    err.key, err.reason = key, reason
    return err


def _parse_value(text: str) -> Any:
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text  # a bare word, e.g. condition=slip


def apply_override(data: dict[str, Any], item: str) -> None:
    """Sets ``a.b[0].c=value`` (or ``a.b.0.c=value``) in ``data``; the value is parsed as TOML. With nothing
    after ``=`` (``time.cfl=``) the key is removed, so that another can take its place (``time.dt=1e-4``)."""
    if "=" not in item:
        raise _plain_error("--set", f"expected key=value, got {item!r}")
    path, _, text = item.partition("=")
    set_key(data, path, _parse_value(text.strip()) if text.strip() else None, item)


def set_key(data: dict[str, Any], path: str, value: Any, item: str | None = None) -> None:
    """Sets the scene key ``path`` (``a.b[0].c`` or ``a.b.0.c``) of ``data`` to ``value``, or removes it when
    ``value`` is None; ``item`` names the override in errors (default: ``path``)."""
    item = path if item is None else item
    parts = [p for p in path.strip().replace("[", ".").replace("]", "").split(".") if p]
    if not parts:
        raise _plain_error("--set", f"empty key in {item!r}")
    node: Any = data
    for i, part in enumerate(parts):
        last = i == len(parts) - 1
        if isinstance(node, list):
            if not part.isdigit() or int(part) >= len(node):
                raise _plain_error(path, f"{part!r} is not an index of a list of {len(node)}")
            idx: Any = int(part)
        elif isinstance(node, dict):
            idx = part
            if not last and idx not in node:
                node[idx] = {}
        else:
            raise _plain_error(path, f"{'.'.join(parts[:i])} is not a table")
        if last and value is None:
            if isinstance(node, dict) and idx not in node:
                raise _plain_error(path, "cannot remove it: the scene has no such key")
            del node[idx]
        elif last:
            node[idx] = value
        else:
            node = node[idx]


def _plain_error(key: str, reason: str) -> SceneError:
    err = SceneError(f"{key}: {reason}")
    err.key, err.reason = key, reason
    return err


#: The scenes shipped with the package (``augmpm scenes`` lists them).
SHIPPED_SCENES = Path(__file__).resolve().parent / "scenes"


def shipped_scenes() -> dict[str, Path]:
    """The shipped scenes by name (``dam_break``, ``paper/fluid_incline_noslip``, ...)."""
    return {p.relative_to(SHIPPED_SCENES).with_suffix("").as_posix(): p for p in sorted(SHIPPED_SCENES.rglob("*.toml"))}


def scene_path(path: str | Path) -> Path:
    """``path`` if it names a file, else the shipped scene of that name (``paper/fluid_incline_noslip``,
    with or without ``.toml``), else ``path`` (so that reading it reports it missing)."""
    path = Path(path)
    if path.exists():
        return path
    name = path.with_suffix("").as_posix() if path.suffix == ".toml" else path.as_posix()
    return shipped_scenes().get(name, path)


#: Cells of a mesh file taken as its surface; quads and polygons are split into triangles (fans).
_SURFACE_CELLS = ("triangle", "quad", "polygon")


@functools.lru_cache(maxsize=32)
def _read_mesh(path: str, stamp: tuple[int, int], key: str) -> tuple[list[list[float]], list[list[int]]]:
    """The vertices and triangles of a mesh file (OBJ, STL, PLY, or any format meshio reads), for the
    file as it was at ``stamp`` (modification time, size)."""
    try:
        mesh = meshio.read(path)
    except Exception as e:  # meshio's readers raise their own errors, and OS and value errors
        raise _plain_error(key, f"cannot read mesh file {path} ({e})") from None
    triangles: list[np.ndarray] = []
    for block in mesh.cells:
        data = np.asarray(block.data, dtype=np.int64)
        if block.type in _SURFACE_CELLS and data.ndim == 2 and data.shape[1] >= 3:
            # Each cell's fan in turn: (0, 1, 2), (0, 2, 3), ...
            fans = [data[:, [0, k, k + 1]] for k in range(1, data.shape[1] - 1)]
            triangles.append(np.stack(fans, axis=1).reshape(-1, 3))
    if not triangles:
        kinds = sorted({block.type for block in mesh.cells}) or ["none"]
        raise _plain_error(key, f"mesh file {path} has no triangles (its cells: {', '.join(kinds)})")
    return np.asarray(mesh.points, dtype=np.float64)[:, :3].tolist(), np.concatenate(triangles).tolist()


def _mesh_entries(data: dict[str, Any]) -> list[tuple[str, dict[str, Any]]]:
    """The walls, bodies and rigid bodies of a scene dict that are meshes, with their keys (``walls[2]``)."""
    entries: list[tuple[str, dict[str, Any]]] = []
    for table, tag in (("walls", "type"), ("bodies", "shape"), ("rigid_bodies", "shape")):
        listed = data.get(table) if isinstance(data, dict) else None
        for i, entry in enumerate(listed if isinstance(listed, list) else []):
            if isinstance(entry, dict) and entry.get(tag) == "mesh":
                entries.append((f"{table}[{i}]", entry))
    return entries


def _with_meshes_read(data: dict[str, Any]) -> dict[str, Any]:
    """``data`` with the ``file`` of every mesh that gives no ``vertices`` read into them."""
    for key, entry in _mesh_entries(data):
        file = entry.get("file")
        if file is None or entry.get("vertices"):
            continue
        try:
            info = Path(file).stat()
        except OSError as e:
            raise _plain_error(f"{key}.file", f"cannot read mesh file {file} ({e.strerror})") from None
        entry["vertices"], entry["triangles"] = _read_mesh(str(file), (info.st_mtime_ns, info.st_size), f"{key}.file")
    return data


def _resolve_mesh_files(data: dict[str, Any], folder: Path) -> None:
    """Makes every relative mesh ``file`` of a scene read from ``folder`` absolute."""
    for _, entry in _mesh_entries(data):
        file = entry.get("file")
        if isinstance(file, str) and not Path(file).is_absolute():
            entry["file"] = str((folder / file).resolve())


def load_scene(path: str | Path, overrides: list[str] | None = None, values: dict[str, Any] | None = None) -> Scene:
    """Reads and validates a TOML scene file, or a shipped scene by name (see :func:`scene_path`), with
    ``key=value`` ``overrides`` (as ``--set``) and then scene ``values`` by key (see :func:`set_key`) applied;
    raises :class:`SceneError` on bad input."""
    path = scene_path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as e:
        raise _plain_error(str(path), f"cannot read scene file ({e.strerror})") from None
    except UnicodeDecodeError as e:
        raise _plain_error(str(path), f"scene file is not UTF-8 text ({e.reason} at byte {e.start})") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise _plain_error(str(path), f"not valid TOML: {e}") from None
    for item in overrides or []:
        apply_override(data, item)
    for key, value in (values or {}).items():
        set_key(data, key, value)
    # A mesh file is named relative to the scene file's folder.
    _resolve_mesh_files(data, path.parent)
    return scene_class(data).from_dict(data)


def scene_class(data: Any) -> Any:
    """:class:`Scene3` for a scene (a dict read from a file) whose ``grid.domain`` has three components,
    else :class:`Scene`."""
    domain = (
        data.get("grid", {}).get("domain") if isinstance(data, dict) and isinstance(data.get("grid"), dict) else None
    )
    return Scene3 if isinstance(domain, list) and len(domain) == 3 else Scene
