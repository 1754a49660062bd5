"""A plan file's text with some keys of some tables set, the rest of the file (comments, order)
as it was: ``with_keys(text, {"settle": {"hold_s": 2700.0}, "bus.simulator.compass":
{"t_s": 0.9}})``. A key found in its table's header section is replaced (its line, comment and
all), a missing key is added under the table's header, a missing table is appended at the end;
a key set to None is removed.

This is the text-level counterpart of `plan.model.revised` (which changes the parsed model and
keeps the file's text): use it when the changed plan must be stored as it ran, as a plan file
given to `gyrostand campaign run` would be (benchmarks and validation runs over variants of a
plan). Only plain ``[table]`` headers and ``key = value`` lines are edited; the result is read
back and every key checked, so a plan whose layout this cannot edit raises `ValueError` instead
of silently running something else.
"""

from __future__ import annotations

import json
import math
import re
import tomllib
from collections.abc import Mapping
from typing import Any

_HEADER = re.compile(r"^\s*\[\s*([^\[\]]+?)\s*\]\s*(#.*)?$")  # [table], not [[array]]
_ANY_HEADER = re.compile(r"^\s*\[")


def toml_value(value: Any) -> str:
    """`value` (bool, int, float, str, or a list of them) as a TOML value."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return ("-inf" if value < 0 else "inf") if math.isinf(value) else repr(value)
    if isinstance(value, str):
        return json.dumps(value)  # a basic string: JSON's escapes are TOML's
    if isinstance(value, list | tuple):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    raise TypeError(f"no TOML value for {value!r}")


def _set_keys(lines: list[str], table: str, keys: Mapping[str, Any]) -> list[str]:
    header = next(
        (i for i, line in enumerate(lines) if (m := _HEADER.match(line)) and m[1] == table), None
    )
    if header is None:
        new = (f"{k} = {toml_value(v)}" for k, v in keys.items() if v is not None)
        return [*lines, "", f"[{table}]", *new]
    end = next(
        (i for i in range(header + 1, len(lines)) if _ANY_HEADER.match(lines[i])), len(lines)
    )
    lines = list(lines)
    missing = []
    for key, value in keys.items():
        pattern = re.compile(rf"^\s*{re.escape(key)}\s*=")
        found = [i for i in range(header + 1, end) if pattern.match(lines[i])]
        if value is None:
            for i in found:
                lines[i] = ""
        elif found:
            lines[found[0]] = f"{key} = {toml_value(value)}"
        else:
            missing.append(f"{key} = {toml_value(value)}")
    return lines[: header + 1] + missing + lines[header + 1 :]


def with_keys(text: str, tables: Mapping[str, Mapping[str, Any]]) -> str:
    """`text` with, per table (dotted name: ``bus.simulator.compass``), the given keys set, or
    removed where None (ValueError when the result does not read back with exactly these)."""
    lines = text.splitlines()
    for table, keys in tables.items():
        if keys:
            lines = _set_keys(lines, table, keys)
    result = "\n".join(lines) + "\n"
    try:
        document = tomllib.loads(result)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"the plan with the keys set is no TOML: {exc}") from None
    for table, keys in tables.items():
        found: Any = document
        for part in table.split("."):
            found = found.get(part, {}) if isinstance(found, dict) else {}
        for key, value in keys.items():
            if value is None and key not in found:
                continue
            if key not in found or found[key] != (
                list(value) if isinstance(value, tuple) else value
            ):
                raise ValueError(f"[{table}] {key}: could not be set to {value!r} in this plan")
    return result
