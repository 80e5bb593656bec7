"""Scene files: TOML in, a validated :class:`Scene` out.

The pydantic models check types, unknown keys and ranges, naming the key of
every error; geometry (polygon orientation and self-intersection, bodies
inside the walls) is checked by the Rust core when the simulation is built.
"""

from __future__ import annotations

import difflib
import json
import math
import tomllib
import typing
from pathlib import Path
from typing import Annotated, Any, Literal

import tomli_w
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, ValidationError, model_validator
from pydantic_core import PydanticCustomError

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
Vec2 = tuple[float, float]
PositiveFloat = Annotated[float, _NUMBER, Field(gt=0, allow_inf_nan=False)]
FiniteFloat = Annotated[float, _NUMBER, Field(allow_inf_nan=False)]
FiniteVec2 = tuple[FiniteFloat, FiniteFloat]
WallCondition = Literal["sticky", "slip", "separate"]
Method = Literal["naive", "augmented"]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_assignment=True)

    # Changed in code, a scene reports a bad value as loading one does: SceneError, naming the key.
    def __setattr__(self, name: str, value: Any) -> None:
        try:
            super().__setattr__(name, value)
        except ValidationError as e:
            raise _scene_error(e) from None


class Grid(_Strict):
    """Domain box [0, Lx] × [0, Ly] (m) and cells along x (h = Lx / resolution)."""

    domain: tuple[PositiveFloat, PositiveFloat]
    resolution: Annotated[int, _INTEGER, Field(ge=2, le=65536)]
    #: Correct the fluid density gathered next to walls for the part of the kernel in the wall.
    density_wall_correction: Annotated[bool, Field(strict=True)] = False

    @property
    def cell_size(self) -> float:
        return self.domain[0] / self.resolution

    @model_validator(mode="after")
    def _whole_cells(self) -> Grid:
        h = self.cell_size
        ny = self.domain[1] / h if h > 0 else math.inf  # h underflows to 0 for a subnormal width
        if not math.isfinite(ny):
            raise ValueError(f"domain height {self.domain[1]} is not a finite number of cells of width {h}")
        if abs(ny - round(ny)) > 1e-9 * max(ny, 1.0) or round(ny) < 2:
            raise ValueError(
                f"domain height {self.domain[1]} is not a whole number (>= 2) of cells of width {self.cell_size}"
            )
        return self


class Time(_Strict):
    """Time step (s) or CFL number, number of steps or end time (s), steps between output frames."""

    dt: PositiveFloat | None = None
    cfl: Annotated[float, _NUMBER, Field(gt=0, le=1)] | None = None
    # Steps are counted in 64-bit integers (Simulation.step takes fewer than 2**63 at once).
    steps: Annotated[int, _INTEGER, Field(ge=0, lt=2**63)] | None = None
    #: End time (s): the run takes ⌈end / dt⌉ steps.
    end: Annotated[float, _NUMBER, Field(ge=0, allow_inf_nan=False)] | None = None
    output_interval: Annotated[int, _INTEGER, Field(ge=1, lt=2**63)]

    @model_validator(mode="after")
    def _dt_or_cfl(self) -> Time:
        if (self.dt is None) == (self.cfl is None):
            raise ValueError("give exactly one of dt and cfl")
        if (self.steps is None) == (self.end is None):
            raise ValueError("give exactly one of steps and end")
        return self

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


class PolygonWall(_Strict):
    """Closed polygon, counter-clockwise, material inside."""

    type: Literal["polygon"]
    vertices: Annotated[list[FiniteVec2], Field(min_length=3)]
    condition: WallCondition | None = None
    velocity: FiniteVec2 = (0.0, 0.0)
    #: Surface speed (m/s) counter-clockwise along the polygon: a belt loop.
    tangential_speed: FiniteFloat = 0.0


class CircleWall(_Strict):
    """Circle; material ``outside`` it (an obstacle) or ``inside`` it (a container)."""

    type: Literal["circle"]
    center: FiniteVec2
    radius: PositiveFloat
    side: Literal["outside", "inside"] = "outside"
    condition: WallCondition | None = None
    velocity: FiniteVec2 = (0.0, 0.0)
    #: Surface speed (m/s) counter-clockwise around the centre: a spinning cylinder.
    tangential_speed: FiniteFloat = 0.0


Wall = Annotated[PolygonWall | CircleWall, Field(discriminator="type")]


class Fluid(_Strict):
    """Weakly compressible Newtonian fluid: p = k((ρ/ρ0)^γ − 1) ≥ min_pressure, σ = −pI + μ(∇v + ∇vᵀ)."""

    type: Literal["fluid"]
    density: PositiveFloat
    stiffness: PositiveFloat
    gamma: PositiveFloat = 7.0
    viscosity: Annotated[float, _NUMBER, Field(ge=0, allow_inf_nan=False)] = 0.0
    min_pressure: Annotated[float, _NUMBER, Field(le=0, allow_inf_nan=False)] = 0.0
    #: Where ρ comes from: "deformation" (ρ0/J, J̇ = J tr ∇v; default) or "grid" (scattered masses, the paper's).
    density_estimate: Literal["deformation", "grid"] = "deformation"


class _Solid(_Strict):
    density: PositiveFloat
    youngs_modulus: PositiveFloat
    poisson_ratio: Annotated[float, _NUMBER, Field(gt=-1.0, lt=0.5)]


class Elastic(_Solid):
    """Fixed-corotated hyperelastic solid."""

    type: Literal["elastic"]


class Stvk(_Solid):
    """St. Venant–Kirchhoff solid."""

    type: Literal["stvk"]


class Snow(_Solid):
    """Stomakhin et al. 2013 snow: fixed-corotated with clamped singular values and hardening."""

    type: Literal["snow"]
    critical_compression: Annotated[float, _NUMBER, Field(gt=0, lt=1)] = 2.5e-2
    critical_stretch: PositiveFloat = 7.5e-3
    hardening: Annotated[float, _NUMBER, Field(ge=0, allow_inf_nan=False)] = 10.0
    jp_min: PositiveFloat = 0.6
    jp_max: PositiveFloat = 20.0


Material = Annotated[Fluid | Elastic | Stvk | Snow, Field(discriminator="type")]


class Seeding(_Strict):
    """Jittered grid: one random point per square of side ``spacing`` (m), or ``per_cell`` per grid cell."""

    spacing: PositiveFloat | None = None
    per_cell: Annotated[int, _INTEGER, Field(ge=1, le=1024)] | None = None

    @model_validator(mode="after")
    def _one_of(self) -> Seeding:
        if self.spacing is not None and self.per_cell is not None:
            raise ValueError("give spacing or per_cell, not both")
        return self


class _Body(_Strict):
    material: Material
    velocity: FiniteVec2 = (0.0, 0.0)
    seeding: Seeding = Field(default_factory=Seeding)


class PolygonBody(_Body):
    """Polygon in a local frame, placed at ``center + scale * vertex``; counter-clockwise."""

    shape: Literal["polygon"]
    vertices: Annotated[list[FiniteVec2], Field(min_length=3)]
    scale: PositiveFloat = 1.0
    center: FiniteVec2 = (0.0, 0.0)


class BoxBody(_Body):
    shape: Literal["box"]
    min: FiniteVec2
    max: FiniteVec2

    @model_validator(mode="after")
    def _ordered(self) -> BoxBody:
        if not (self.max[0] > self.min[0] and self.max[1] > self.min[1]):
            raise ValueError("max must exceed min along both axes")
        return self


class CircleBody(_Body):
    shape: Literal["circle"]
    center: FiniteVec2
    radius: PositiveFloat


Body = Annotated[PolygonBody | BoxBody | CircleBody, Field(discriminator="shape")]


class Augmented(_Strict):
    """Augmented grid: exclusion distance δ (Fig. 3) and largest boundary-point spacing, in cell widths."""

    delta: Annotated[float, _NUMBER, Field(ge=0, lt=1.5)] = 0.25
    spacing: Annotated[float, _NUMBER, Field(gt=0.05, le=1.0)] = 1.0
    #: "stable" (default: energy-stable transfer fitted to the wall value) or "paper" (the paper's φ transfer).
    transfer: Literal["stable", "paper"] = "stable"


class Scene(_Strict):
    """A whole scene. Build one in code with keyword arguments or :meth:`from_dict`."""

    # Built in code, a scene reports a bad value as loading one does: SceneError, naming the dotted key.
    # (Only here: pydantic calls an overridden __init__ of nested models too, which would lose the path.)
    def __init__(self, **data: Any) -> None:
        try:
            super().__init__(**data)
        except ValidationError as e:
            raise _scene_error(e) from None

    name: str = ""
    seed: Annotated[int, _INTEGER, Field(ge=0, lt=2**64)] = 0
    gravity: FiniteVec2 = (0.0, -9.81)
    grid: Grid
    time: Time
    #: How walls act on the grid: "augmented" (default: the paper's augmented grid) or "naive" (grid nodes on
    #: the wall side take the wall's condition). ``Simulation(scene, method)`` and ``--method`` override it.
    method: Method = "augmented"
    wall_condition: WallCondition = "sticky"
    walls: list[Wall] = Field(default_factory=list)
    bodies: Annotated[list[Body], Field(min_length=1)]
    augmented: Augmented = Field(default_factory=Augmented)
    #: Floating-point precision of the engine: "f64" (default) or "f32" (same code, single precision).
    precision: Literal["f32", "f64"] = "f64"

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Scene:
        """Validates a plain dict (as read from TOML); raises :class:`SceneError` naming the key."""
        try:
            return cls.model_validate(data)
        except ValidationError as e:
            raise _scene_error(e) from None

    def to_dict(self) -> dict[str, Any]:
        return self.model_dump(mode="json", exclude_none=True)

    def to_json(self) -> str:
        return json.dumps(self.to_dict())

    def to_toml(self) -> str:
        return tomli_w.dumps(self.to_dict())

    def with_overrides(self, overrides: list[str]) -> Scene:
        """A copy with ``key=value`` overrides applied (see :func:`apply_override`)."""
        data = self.to_dict()
        for item in overrides:
            apply_override(data, item)
        return Scene.from_dict(data)


def _format_loc(loc: tuple[Any, ...]) -> str:
    key = ""
    for part in loc:
        if isinstance(part, int):
            key += f"[{part}]"
        elif part in ("polygon", "circle", "box", "fluid", "elastic", "stvk", "snow") and key:
            continue  # the tag of a discriminated union, not a key of the file
        else:
            key += ("." if key else "") + str(part)
    return key or "scene"


def _scene_keys() -> set[str]:
    """Every key a scene's tables can hold (the fields of all its models)."""
    keys: set[str] = set()
    pending: list[type[BaseModel]] = [Scene]
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
        keys = _scene_keys() - {str(loc[-1])} if loc else set()
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
        if last and not text.strip():
            if isinstance(node, dict) and idx not in node:
                raise _plain_error(path, "cannot remove it: the scene has no such key")
            del node[idx]
        elif last:
            node[idx] = _parse_value(text.strip())
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


def load_scene(path: str | Path, overrides: list[str] | None = None) -> Scene:
    """Reads and validates a TOML scene file, or a shipped scene by name (see :func:`scene_path`);
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
    return Scene.from_dict(data)
