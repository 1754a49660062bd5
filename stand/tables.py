"""pydantic's validation errors of a TOML document as problems in the document's own terms:
``[bus.simulator.faults] drop: unknown key``, ``[[trials]] 3 period_s: must be > 0``.

Shared by the readers of TOML documents (the campaign plan, a simulate schedule), so that every
one of them reports every problem at once, each with its path, in the same words."""

from __future__ import annotations

import ast
import inspect
from collections.abc import Iterable
from typing import Any, get_args, get_origin

from pydantic import BaseModel, ConfigDict
from pydantic_core import ErrorDetails


def attribute_docs(schema: dict[str, Any], model: type[BaseModel]) -> None:
    """The JSON Schema's description of each field without one: its attribute docstring (the
    string under it in the class body, as pydantic's `use_attribute_docstrings` reads it).

    Read when a schema is made, not when a model class is: on Python < 3.13 pydantic's option
    finds each class's source by walking the call stack with `inspect.getmodule`, a scan of
    every loaded module per frame (~40 % of `plan check`'s start-up, bench/bench_cli_startup.py)."""
    properties = schema.get("properties", {})
    for cls in reversed(model.__mro__):
        if not (isinstance(cls, type) and issubclass(cls, BaseModel)) or cls is BaseModel:
            continue
        try:
            body = ast.parse(inspect.cleandoc("\n" + inspect.getsource(cls))).body[0]
        except (OSError, TypeError, SyntaxError, IndexError):  # a class made by create_model
            continue
        statements = body.body if isinstance(body, ast.ClassDef) else []
        for statement, after in zip(statements, statements[1:], strict=False):
            if (
                isinstance(statement, ast.AnnAssign)
                and isinstance(statement.target, ast.Name)
                and isinstance(after, ast.Expr)
                and isinstance(after.value, ast.Constant)
                and isinstance(after.value.value, str)
                and (field := properties.get(statement.target.id)) is not None
            ):
                field.setdefault("description", inspect.cleandoc(after.value.value))


TABLE_CONFIG = ConfigDict(
    extra="forbid",
    frozen=True,
    strict=True,
    allow_inf_nan=False,
    json_schema_extra=attribute_docs,
)
"""A table of a TOML document: frozen; unknown keys refused; strict types (no "1.5" for 1.5, no
true for 1); finite numbers; the attribute docstrings of its fields their descriptions in the
JSON Schema (`attribute_docs`)."""


class Problems(ValueError):
    """What a cross-field rule found in one table, as (key, message) pairs; a key may be a
    dotted path into the table's subtables."""

    def __init__(self, problems: list[tuple[str, str]]) -> None:
        self.problems = problems
        super().__init__("; ".join(f"{key}: {message}" for key, message in problems))


def check(problems: list[tuple[str, str]]) -> None:
    """Raise `Problems` when there are any (from a model validator)."""
    if problems:
        raise Problems(problems)


_BOUNDS = {
    "greater_than": ">",
    "greater_than_equal": ">=",
    "less_than": "<",
    "less_than_equal": "<=",
}
_MESSAGES = {
    "missing": "missing",
    "extra_forbidden": "unknown key",
    "float_type": "must be a finite number",
    "finite_number": "must be a finite number",
    "int_type": "must be an integer",
    "string_type": "must be a non-empty string",
    "string_pattern_mismatch": "must be a non-empty string",
    "bool_type": "must be true or false",
    "model_type": "must be a table",
    "dict_type": "must be a table",
    "tuple_type": "must be an array",
    "list_type": "must be an array",
}


def problems(model: type[BaseModel], errors: Iterable[ErrorDetails]) -> list[str]:
    """The errors of validating `model` as ``path: message`` lines, each problem once."""
    found: list[str] = []
    for error in errors:
        loc, cause = error["loc"], error.get("ctx", {}).get("error")
        if isinstance(cause, Problems):
            lines = [(loc + tuple(key.split(".")), message) for key, message in cause.problems]
        elif error["type"] == "value_error" and cause is not None:
            lines = [(loc, str(cause))]
        else:
            lines = [(loc, _message(error))]
        for where, message in lines:
            line = f"{path(model, where)}: {message}"
            if line not in found:
                found.append(line)
    return found


def _message(error: ErrorDetails) -> str:
    kind, ctx = error["type"], error.get("ctx", {})
    if kind in _BOUNDS:
        return f"must be {_BOUNDS[kind]} {next(iter(ctx.values())):g}"
    if kind == "literal_error":
        expected = str(ctx["expected"]).replace(" or ", ", ")
        return f"must be one of {expected}, not {error['input']!r}"
    if kind == "too_short" and ctx.get("min_length") == 1:
        return "must not be empty"
    return _MESSAGES.get(kind, error["msg"])


def path(model: type[BaseModel], loc: tuple[int | str, ...]) -> str:
    """``[bus.simulator] seed``, ``[[trials]] 3 role``, ``[analysis]``, or a top-level key."""
    tables: list[str] = []
    array, row, key = False, None, None
    current: type | None = model
    for part in loc:
        if key is not None:
            break
        if isinstance(part, int):
            row = part + 1
            continue
        table, array_field = _table(current, part)
        if table is None:
            key = part
        else:
            tables.append(part)
            array = array_field
            current = table
    if array:
        where = f"[[{'.'.join(tables)}]]" + ("" if row is None else f" {row}")
    else:
        where = f"[{'.'.join(tables)}]" if tables else ""
    return " ".join(p for p in (where, key) if p)


def _table(model: type | None, name: str) -> tuple[type | None, bool]:
    """The model of table `name` of `model` (``dict`` for a free-form table; None for a key),
    and whether it is an array of tables."""
    fields = model.model_fields if isinstance(model, type) and issubclass(model, BaseModel) else {}
    field = fields.get(name)
    if field is None:
        return None, False
    array = get_origin(field.annotation) in (tuple, list)
    return _model_in(field.annotation), array


def _model_in(annotation: Any) -> type | None:
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    if get_origin(annotation) is dict:
        return dict
    for arg in get_args(annotation):
        found = _model_in(arg)
        if found is not None:
            return found
    return None
