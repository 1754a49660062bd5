"""Frozen dataclasses to plain JSON and back, exactly, driven by their type hints: the stored
analysis of a campaign (`report.stored`) is rebuilt from its `AnalysisRun` instead of being
computed again.

    encode(value) -> JSON types          decode(cls, data) -> an instance of cls

Non-finite floats are kept as the strings "nan", "inf", "-inf" (JSON has no NaN, PostgreSQL's
JSON refuses it), numpy arrays as {"array": nested lists, "dtype": name}, tuples as lists.
Written here rather than with pydantic's TypeAdapter: that builds a validator per type at first
use (about 0.3 s for the analysis's types in a fresh process), more than the decode itself.
"""

from __future__ import annotations

import functools
import math
import types
import typing
from dataclasses import fields, is_dataclass
from typing import Any

import numpy as np

_NON_FINITE = {"nan": math.nan, "inf": math.inf, "-inf": -math.inf}


def encode(value: Any) -> Any:
    """Plain JSON types for a dataclass tree (see the module docstring)."""
    if is_dataclass(value) and not isinstance(value, type):
        return {f.name: encode(getattr(value, f.name)) for f in fields(value)}
    if isinstance(value, np.ndarray):
        return {"array": encode(value.tolist()), "dtype": value.dtype.str}
    if isinstance(value, dict):
        return {_key(k): encode(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [encode(v) for v in value]
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return float(value) if math.isfinite(value) else str(float(value))
    if value is None or isinstance(value, str):
        return value
    raise TypeError(f"cannot encode a {type(value).__name__} as JSON")


def _key(key: Any) -> str:
    if isinstance(key, str):
        return key
    if isinstance(key, int | np.integer) and not isinstance(key, bool):
        return str(int(key))
    raise TypeError(f"cannot encode a {type(key).__name__} key as JSON")


def decode(cls: Any, data: Any) -> Any:
    """The value of type `cls` that `encode` turned into `data` (TypeError: it does not fit)."""
    origin = typing.get_origin(cls)
    if cls is Any:
        return data
    if origin in (typing.Union, types.UnionType):
        options = typing.get_args(cls)
        if data is None and type(None) in options:
            return None
        errors = []
        for option in (o for o in options if o is not type(None)):
            try:
                return decode(option, data)
            except (TypeError, KeyError, ValueError) as error:
                errors.append(str(error))
        raise TypeError(f"{data!r:.60} fits none of {cls}: {'; '.join(errors)}")
    if origin is typing.Literal:
        if data not in typing.get_args(cls):
            raise TypeError(f"{data!r} is not one of {typing.get_args(cls)}")
        return data
    if origin is tuple:
        args = typing.get_args(cls)
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(decode(args[0], v) for v in _list(data))
        items = _list(data)
        if len(items) != len(args):
            raise TypeError(f"{len(items)} items for {cls}")
        return tuple(decode(a, v) for a, v in zip(args, items, strict=True))
    if origin is list:
        return [decode(typing.get_args(cls)[0], v) for v in _list(data)]
    if origin is dict:
        key, value = typing.get_args(cls)
        if not isinstance(data, dict):
            raise TypeError(f"{data!r:.60} is not an object")
        return {(int(k) if key is int else k): decode(value, v) for k, v in data.items()}
    if cls is np.ndarray:
        if not isinstance(data, dict) or "array" not in data:
            raise TypeError(f"{data!r:.60} is not an array")
        dtype = np.dtype(data["dtype"])
        return np.array(_floats(data["array"]) if dtype.kind == "f" else data["array"], dtype)
    if isinstance(cls, type) and is_dataclass(cls):
        if not isinstance(data, dict):
            raise TypeError(f"{data!r:.60} is not a {cls.__name__}")
        hints = _hints(cls)
        return cls(**{f.name: decode(hints[f.name], data[f.name]) for f in fields(cls) if f.init})
    if cls is float:
        if isinstance(data, str) and data in _NON_FINITE:
            return _NON_FINITE[data]
        if isinstance(data, int | float) and not isinstance(data, bool):
            return float(data)
        raise TypeError(f"{data!r:.60} is not a number")
    if cls in (int, str, bool):
        if type(data) is not cls:
            raise TypeError(f"{data!r:.60} is not a {cls.__name__}")
        return data
    if cls is type(None) and data is None:
        return None
    raise TypeError(f"cannot decode {cls}")


def _list(data: Any) -> list[Any]:
    if not isinstance(data, list):
        raise TypeError(f"{data!r:.60} is not a list")
    return data


def _floats(data: Any) -> Any:
    if isinstance(data, list):
        return [_floats(v) for v in data]
    return _NON_FINITE[data] if isinstance(data, str) else data


@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)
