"""A JSON Schema (draft 2020-12) of the scenario format (``mpcform keys --json-schema``), generated
from the key table :data:`~mpcform.scenario.schema.SCHEMA`.

It describes a scenario file as parsed TOML: tables, key names (no others:
``additionalProperties`` false), types, enums, lower bounds, defaults, the required keys and,
per variant of a table (``shape`` or ``kind``), the keys that variant requires and the keys it
does not take. Descriptions carry each key's meaning and unit. Some rules stay with
``mpcform validate``: vector lengths depend on ``dim`` (the schema allows 2 or 3 numbers),
numbers must be finite, and the checks between keys (centred offsets, starts clear of obstacles,
gain * dt <= 1, ...).
"""

from __future__ import annotations

from typing import Any

from mpcform.reference.keyframes import GROUPS
from mpcform.scenario.parse import MAX_NAME_CHARS, NAME_PATTERN
from mpcform.scenario.schema import FORMAT_VERSION, SCHEMA, TABLES, Key, Table, listing

DRAFT = "https://json-schema.org/draft/2020-12/schema"
NUMBER: dict[str, Any] = {"type": "number"}
VECTOR: dict[str, Any] = {"type": "array", "items": NUMBER, "minItems": 2, "maxItems": 3}
INDEX: dict[str, Any] = {"type": "integer", "minimum": 0}


WIND = {
    "type": "object",
    "description": "Mean wind and seeded gusts acting through drag (mpcform.sim.wind).",
    "properties": {
        "mean": {**VECTOR, "description": "mean wind [m/s], d numbers"},
        "gust_std": {"type": "number", "minimum": 0, "description": "gust standard deviation [m/s]"},
        "gust_time": {"type": "number", "exclusiveMinimum": 0, "description": "gust correlation time [s]"},
        "gust_bound": {"type": "number", "minimum": 0, "description": "per-axis clip [m/s] (inf: none)"},
        "gust_field": {"enum": ["per_drone", "shared"]},
    },
    "required": ["mean"],
    "additionalProperties": False,
}


def scenario_json_schema() -> dict[str, Any]:
    """The JSON Schema of a scenario document (a dict, ready for :func:`json.dumps`)."""
    top = _object(TABLES[""])
    for table in SCHEMA:
        if not table.name or "." in table.name:  # keyframes and [controller.solve]: inside their table
            continue
        ref = {"$ref": f"#/$defs/{table.name}"}
        top["properties"][table.name] = (
            {"type": "array", "items": ref, "description": table.doc} if table.array else ref
        )
        if table.required:
            top["required"].append(table.name)
    top["properties"]["name"] |= {"pattern": f"^{NAME_PATTERN}$", "maxLength": MAX_NAME_CHARS}
    defs = {t.name.replace(".", "_"): _object(t) for t in SCHEMA if t.name}
    return {
        "$schema": DRAFT,
        "title": f"mpcform scenario (format version {FORMAT_VERSION})",
        "description": "A scenario file of mpcform (TOML). All lengths in metres, angles in radians, "
        "times in seconds.",
        **top,
        "$defs": defs,
    }


def _object(table: Table) -> dict[str, Any]:
    """The schema of one table: its keys, the required ones and the rules of its variants."""
    out: dict[str, Any] = {
        "type": "object",
        "description": table.doc,
        "properties": {key.name: _key(key, table) for key in table.keys},
        "required": [k.name for k in table.keys if k.required and not k.when],
        "additionalProperties": False,
    }
    if table.selector is not None:
        selector = table.key(table.selector)
        if selector.default is None:  # a selector with a default ([[obstacles]] shape) may be left out
            out["required"] = list(dict.fromkeys([*out["required"], table.selector]))
        variants = selector.choices
        rules = []
        for variant in variants:
            needs = [k.name for k in table.keys if k.required and variant in k.when]
            others = {k.name: False for k in table.keys if k.when and variant not in k.when}
            then: dict[str, Any] = {}
            if needs:
                then["required"] = needs
            if others:
                then["properties"] = others
            if then:
                rules.append(
                    {
                        "if": {
                            "properties": {table.selector: {"const": variant}},
                            **({} if variant == selector.default else {"required": [table.selector]}),
                        },
                        "then": then,
                    }
                )
        if rules:
            out["allOf"] = rules
    return out


def _key(key: Key, table: Table) -> dict[str, Any]:
    out = dict(_type(key, table))
    text = key.doc + (f" [{key.unit}]" if key.unit else "")
    if key.when:
        text += f" Only with {table.selector} = {listing(key.when)}."
    if key.shown_default is not None:
        text += f" Default: {key.shown_default}."
    out["description"] = text
    if key.default is not None and not key.required:
        out["default"] = key.default
    if key.choices:
        out["enum"] = list(key.choices)
    return out


def _type(key: Key, table: Table) -> dict[str, Any]:
    if key.type in ("int", "float"):
        out: dict[str, Any] = {"type": "integer" if key.type == "int" else "number"}
        if key.bound:
            op, low = key.bound.split()
            value = int(low) if key.type == "int" else float(low)
            out["exclusiveMinimum" if op == ">" else "minimum"] = value
        return {"anyOf": [out, {"enum": list(key.names)}]} if key.names else out
    if key.type == "bool":
        return {"type": "boolean"}
    if key.type == "string":
        return {"type": "string"}
    if key.type in ("vector", "bounds"):
        return dict(VECTOR)
    if key.type == "rotation":
        return {"anyOf": [NUMBER, {"type": "array", "items": NUMBER, "minItems": 3, "maxItems": 3}]}
    if key.type == "points":
        return {"type": "array", "items": VECTOR, "minItems": 1}
    if key.type == "indices":
        return {"type": "array", "items": INDEX}
    if key.type == "pairs":
        return {"type": "array", "items": {"type": "array", "items": INDEX, "minItems": 2, "maxItems": 2}}
    if key.type == "tables":  # the mission's keyframes
        return {"type": "array", "items": {"$ref": "#/$defs/reference_keyframes"}, "minItems": 1}
    if key.name == "template":  # a keyframe's template switch: a [template] table
        return {"$ref": "#/$defs/template"}
    if key.name == "solve":  # [controller.solve]
        return {"$ref": "#/$defs/controller_solve"}
    if key.name == "wind":  # [plant.wind]
        return WIND
    group = {"type": "number", "exclusiveMinimum": 0}  # max_velocity, max_acceleration, max_jerk
    return {"type": "object", "properties": dict.fromkeys(GROUPS, group), "additionalProperties": False}
