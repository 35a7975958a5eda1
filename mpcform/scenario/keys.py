"""The scenario key reference: every key of :data:`~mpcform.scenario.schema.SCHEMA` as markdown
tables (``mpcform keys``; committed in ``scenarios/README.md``)."""

from __future__ import annotations

from mpcform.scenario.schema import SCHEMA, Key, listing


def key_reference_markdown() -> str:
    """Every scenario key as markdown tables (key, type, default, unit, meaning), per table."""
    lines = ["All lengths in metres, angles in radians, times in seconds.", ""]
    for table in SCHEMA:
        need = "required" if table.required else "optional"
        lines += [f"### {table.title}", "", f"{table.doc} ({need})", ""]
        lines += ["| key | type | default | unit | meaning |", "| --- | --- | --- | --- | --- |"]
        for key in table.keys:
            doc = key.doc
            if key.when:
                doc += f" Only with `{table.selector}` = {listing(key.when, '`')}."
            cells = (f"`{key.name}`", _type_text(key), _default_text(key), key.unit, doc)
            lines.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
        lines.append("")
    return "\n".join(lines)


def _type_text(key: Key) -> str:
    base = {
        "int": "integer",
        "float": "float",
        "bool": "boolean",
        "string": "string",
        "vector": "d numbers",
        "bounds": "d numbers (+-inf allowed)",
        "rotation": "float (d = 2) or 3 numbers (d = 3)",
        "points": "n rows of d numbers",
        "table": "inline table",
        "tables": "array of tables",
        "indices": "list of integers >= 0",
        "pairs": "list of [i, j] integer pairs",
    }[key.type]
    if key.choices:
        quote = '"' if key.type == "string" else ""
        return f"{base}: {listing(key.choices, quote)}"
    if key.names:
        names = listing(key.names, '"')
        return f"{base}{key.bound_text} or {names}"
    return base + key.bound_text


def _default_text(key: Key) -> str:
    if key.required:
        return "required"
    if key.shown_default is not None:
        return key.shown_default
    if key.default is None:
        return "unset"
    if isinstance(key.default, bool):
        return str(key.default).lower()
    if isinstance(key.default, str):
        return f'"{key.default}"'
    return f"{key.default:g}"
