"""The configuration reference, generated from the schema (``marsupial config``).

Everything comes from the pydantic JSON schema of :class:`mission.config.schema.Config`: names,
types, defaults and constraints, and the meaning and unit of each field from its ``description=``
(the one place a field is documented). A test (``tests/unit/config/test_config_reference.py``) fails when
a field's description does not start with its unit, and keeps docs/configuration.md's table identical to
:func:`markdown_table`. Units in square brackets; ``[-]`` is dimensionless.
"""
from __future__ import annotations

import json
from typing import Any

from mission.config.schema import Config

def _resolve(schema: dict[str, Any], node: dict[str, Any]) -> dict[str, Any]:
    ref = node.get("$ref")
    return schema["$defs"][ref.rsplit("/", 1)[1]] if ref else node


def _type(schema: dict[str, Any], p: dict[str, Any]) -> str:
    if "anyOf" in p:
        kinds = [_type(schema, q) for q in p["anyOf"]]
        return " or ".join(k for k in kinds if k != "null") + (" or none" if "null" in kinds else "")
    if "enum" in p:
        return " \\| ".join(json.dumps(v) for v in p["enum"])
    if "const" in p:
        return json.dumps(p["const"])
    if "$ref" in p:
        return "table"
    kind = p.get("type", "any")
    if kind == "array":
        if "prefixItems" in p:
            return f"[{', '.join(_type(schema, q) for q in p['prefixItems'])}]"
        return f"list of {_type(schema, p.get('items', {}))}"
    return {"number": "float", "integer": "int", "string": "str", "boolean": "bool", "null": "null"}.get(kind, kind)


def _rule(p: dict[str, Any]) -> str:
    parts = []
    for key, op in (("exclusiveMinimum", ">"), ("minimum", ">="), ("exclusiveMaximum", "<"), ("maximum", "<=")):
        for q in [p, *p.get("anyOf", [])]:
            if key in q:
                parts.append(f"{op} {q[key]:g}")
    if "pattern" in p:
        parts.append(f"matches `{p['pattern']}`")
    return ", ".join(parts)


def fields() -> list[dict[str, str]]:
    """One row per configuration field: key, type, default, rule, doc (meaning with its unit)."""
    schema = Config.model_json_schema()
    rows = []

    def walk(prefix: str, model: dict[str, Any]) -> None:
        for name, p in model.get("properties", {}).items():
            key = f"{prefix}{name}"
            items = p.get("items", {})
            doc = p.get("description", "")
            rows.append({"key": key, "type": _type(schema, p), "default": json.dumps(p["default"]) if "default" in p else "required",
                         "rule": _rule(p), "doc": doc})
            if "$ref" in items:  # a list of tables (obstacles)
                walk(f"{key}[].", _resolve(schema, items))
            if "$ref" in p:  # a sub-table (carrier.mavlink, carrier.ros2)
                walk(f"{key}.", _resolve(schema, p))

    for section, ref in schema["properties"].items():
        walk(f"{section}.", _resolve(schema, ref))
    return rows


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def markdown_table() -> str:
    """The reference as a Markdown table (docs/configuration.md's *Configuration reference*)."""
    lines = ["| field | type | default | rule | meaning [unit] |", "|---|---|---|---|---|"]
    for r in fields():
        lines.append(f"| `{r['key']}` | {r['type']} | `{r['default']}` | {_cell(r['rule'])} | {_cell(r['doc'])} |")
    return "\n".join(lines)


def text_table() -> str:
    """The reference for a terminal: one block per field."""
    out = []
    for r in fields():
        rule = f", {r['rule']}" if r["rule"] else ""
        out.append(f"{r['key']}  ({r['type']}, default {r['default']}{rule})\n    {r['doc']}")
    return "\n".join(out)


def effective(cfg: Config) -> str:
    """Every field's value in ``cfg`` (file, then defaults), one ``section.field = value`` a line."""
    lines = []
    for section, values in cfg.model_dump(mode="json").items():
        for name, value in values.items():
            lines.append(f"{section}.{name} = {json.dumps(value)}")
    return "\n".join(lines)


def json_schema() -> str:
    return json.dumps(Config.model_json_schema(), indent=2)
