"""The scene reference (Markdown), generated from the scene schema: `augmpm schema --markdown`.

The README's "Scene reference" section is this text; a test keeps the two equal.
"""

from __future__ import annotations

import json
from typing import Any

from augmpm.scene import SCHEMA, SCHEMA3

_DEFS = {**SCHEMA3["$defs"], **SCHEMA["$defs"]}


def _resolve(schema: dict[str, Any]) -> dict[str, Any]:
    ref = schema.get("$ref")
    return {**_DEFS[ref.rsplit("/", 1)[-1]], **{k: v for k, v in schema.items() if k != "$ref"}} if ref else schema


def _one_line(text: str | None) -> str:
    return " ".join((text or "").split())


def _choices(schema: dict[str, Any]) -> list[dict[str, Any]] | None:
    """The options of a choice of names (`sticky`, `slip`, ...), through an optional one."""
    schema = _resolve(schema)
    if "anyOf" in schema:
        schema = _resolve(next(o for o in schema["anyOf"] if o.get("type") != "null"))
    options = schema.get("oneOf")
    return options if options and all("const" in o for o in options) else None


def _number(x: Any) -> str:
    return "∞" if x is None else (str(int(x)) if isinstance(x, float) and x.is_integer() else str(x))


def _infinite(schema: dict[str, Any]) -> dict[str, Any] | None:
    """The number option of a key that also takes "inf", or None."""
    options = schema.get("anyOf", [])
    if any(o.get("const") == "inf" for o in options):
        return next(o for o in options if o.get("type") == "number")
    return None


def _range(schema: dict[str, Any]) -> str:
    schema = _resolve(schema)
    if (options := _choices(schema)) is not None:
        return ", ".join(f"`{o['const']}`" for o in options)
    if schema.get("type") == "array" and _choices(schema["items"]) is not None:
        return "each of " + _range(schema["items"])
    if (number := _infinite(schema)) is not None:
        return _range(number).replace("∞)", "∞]")
    target = schema
    prefix = ""
    while target.get("type") in ("array", ["array", "null"]) and "items" in target:
        target, prefix = target["items"], "each "
    lo = ("(", target["exclusiveMinimum"]) if "exclusiveMinimum" in target else ("[", target.get("minimum"))
    hi = (")", target["exclusiveMaximum"]) if "exclusiveMaximum" in target else ("]", target.get("maximum"))
    if lo[1] is None and hi[1] is None:
        return "any" if schema.get("unbounded") else ""
    if hi[1] is not None and hi[1] >= 2**63 - 1:
        hi = (")", None)
    left = "(−∞" if lo[1] is None else f"{lo[0]}{_number(lo[1])}"
    right = "∞)" if hi[1] is None else f"{_number(hi[1])}{hi[0]}"
    return f"{prefix}{left}, {right}"


def _type(schema: dict[str, Any]) -> str:
    schema = _resolve(schema)
    if _choices(schema) is not None:
        return "name"
    if _infinite(schema) is not None:
        return 'number or `"inf"`'
    if "anyOf" in schema:
        return _type(next(o for o in schema["anyOf"] if o.get("type") != "null"))
    kinds = schema.get("type")
    kind = next((k for k in ([kinds] if isinstance(kinds, str) else kinds or []) if k != "null"), None)
    if kind == "array":
        items = _resolve(schema["items"])
        n = schema.get("minItems")
        if items.get("type") == "number" and n == 2 == schema.get("maxItems"):
            return "[x, y]"
        inner = _type(items)
        return f"list of {inner}"
    return {"number": "number", "integer": "integer", "boolean": "boolean", "string": "string"}.get(kind, "table")


def _default(schema: dict[str, Any], required: bool) -> str:
    if required:
        return "required"
    if "default" not in schema or schema["default"] is None or isinstance(schema["default"], dict):
        return ""
    return f"`{json.dumps(schema['default'], ensure_ascii=False)}`"


def _doc(schema: dict[str, Any]) -> str:
    doc = _one_line(schema.get("description"))
    if schema.get("type") == "array" and _choices(schema["items"]) is not None:
        schema = {**schema, "oneOf": _choices(schema["items"])}
    if (options := _choices(schema)) is not None:
        doc += " " + "; ".join(f"`{o['const']}`: {_one_line(o.get('description')).rstrip('.')}" for o in options) + "."
    return doc.replace("|", "\\|")


def _table(title: str, doc: str, properties: dict[str, Any], required: set[str]) -> list[str]:
    header = ["| key | type | default | range | unit | what |", "|---|---|---|---|---|---|"]
    lines = [f"#### `{title}`", "", doc, "", *header]
    for key, prop in properties.items():
        if "const" in prop:
            continue  # the tag, named in the title
        unit = prop.get("unit", "")
        row = [f"`{key}`", _type(prop), _default(prop, key in required), _range(prop), unit, _doc(_resolve(prop))]
        lines.append("| " + " | ".join(row) + " |")
    return [*lines, ""]


def _tables(path: str, schema: dict[str, Any], out: list[list[str]]) -> None:
    """Appends the tables of `schema` (a table, or a choice of tables) at `path`, then those nested in it."""
    schema = _resolve(schema)
    options = schema.get("oneOf")
    if options and not all("const" in o for o in options):
        tag = next(k for k, p in options[0]["properties"].items() if "const" in p)
        for option in options:
            name = option["properties"][tag]["const"]
            props = {**schema.get("properties", {}), **option.get("properties", {})}
            required = {*schema.get("required", []), *option.get("required", [])}
            doc = _one_line(option.get("description"))
            out.append(_table(f'{path} ({tag} = "{name}")', doc, props, required))
        _nested(path, schema.get("properties", {}), out)  # shared by the options
        for option in options:
            _nested(path, option.get("properties", {}), out)
        return
    doc = _one_line(schema.get("description"))
    out.append(_table(path or "scene", doc, schema["properties"], set(schema.get("required", []))))
    _nested(path, schema["properties"], out)


def _nested(path: str, properties: dict[str, Any], out: list[list[str]]) -> None:
    for key, prop in properties.items():
        if "anyOf" in prop:  # an optional table: its table
            prop = next(o for o in prop["anyOf"] if o.get("type") != "null")
        # A table's own doc, not the doc of the key that holds it.
        prop = _DEFS[prop["$ref"].rsplit("/", 1)[-1]] if "$ref" in prop else prop
        child = f"{path}.{key}" if path else key
        if prop.get("type") == "array" and "$ref" in prop.get("items", {}):
            if _choices(prop["items"]) is None:  # a list of names has no table of its own
                _tables(f"{child}[]", prop["items"], out)
        elif (prop.get("type") == "object" or "oneOf" in prop) and _choices(prop) is None:
            if any(section[0].startswith(f"#### `{child}") for section in out):
                continue
            _tables(child, prop, out)


def scene_reference() -> str:
    """Every scene key, table by table: type, default, range, unit and doc line, from the schemas; the
    tables of 3D scenes that differ from the 2D ones follow, marked (3D)."""
    out: list[list[str]] = []
    _tables("", SCHEMA, out)
    out3: list[list[str]] = []
    _tables("", SCHEMA3, out3)
    seen = {tuple(section) for section in out}
    out.append(["#### 3D scenes", "", "A scene whose `grid.domain` has three components is 3D; its tables:", ""])
    for section in out3:
        if tuple(section) not in seen:
            out.append([section[0] + " (3D)", *section[1:]])
    return "\n".join(line for section in out for line in section).rstrip() + "\n"
