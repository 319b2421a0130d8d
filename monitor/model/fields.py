"""A statistic's model (``BiasModel``, ``FlowModel``, ``HoldModel``, ``LeverModel``,
``StrokeModel``) as the JSON object of the model file's header and back, from its dataclass
fields: one rule for every member instead of a hand-written pair each.

A field's type says how it is written and read: ``int`` and ``float`` as numbers (a NaN
threshold stays NaN), an array as nested lists with an infinite entry as ``null`` (JSON has
no Infinity), a tuple as a list, a nested model by its own fields, ``None`` as absent.  A
field declared with ``OMIT_AT_DEFAULT`` is left out while at its default, so files that do
not use it stay as they were before it existed; a missing key takes the field's default,
and a missing key without one is a ``KeyError`` (the model file's loader reports it).  The
model's own ``__post_init__`` then checks the values.
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from collections.abc import Mapping
from typing import Any, TypeVar

import numpy as np

T = TypeVar("T")

#: ``dataclasses.field(default=..., metadata=OMIT_AT_DEFAULT)``: not written at its default.
OMIT_AT_DEFAULT = {"omit_at_default": True}


def fields_to_dict(model: Any) -> dict[str, object]:
    """The model's fields as a JSON-ready dict (see the module's docstring)."""
    out: dict[str, object] = {}
    for f in dataclasses.fields(model):
        value = getattr(model, f.name)
        if value is None or (f.metadata.get("omit_at_default") and value == f.default):
            continue
        out[f.name] = _plain(value)
    return out


def fields_from_dict(cls: type[T], d: Mapping[str, Any]) -> T:
    """``cls`` from a dict ``fields_to_dict`` wrote (or an older file lacking defaults)."""
    hints = typing.get_type_hints(cls)
    kwargs: dict[str, Any] = {}
    for f in dataclasses.fields(cls):  # type: ignore[arg-type]
        if f.name in d:
            kwargs[f.name] = _typed(hints[f.name], d[f.name])
        elif f.default is dataclasses.MISSING:
            raise KeyError(f.name)
    return cls(**kwargs)


def _plain(value: Any) -> object:
    if dataclasses.is_dataclass(value):
        return fields_to_dict(value)
    if isinstance(value, np.ndarray):
        return _lists(value.tolist())
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    return float(value)


def _lists(v: Any) -> Any:
    if isinstance(v, list):
        return [_lists(x) for x in v]
    return None if math.isinf(v) else float(v)


def _typed(tp: Any, v: Any) -> Any:
    args = typing.get_args(tp)
    if isinstance(tp, types.UnionType) or typing.get_origin(tp) is typing.Union:
        (inner,) = (a for a in args if a is not type(None))
        return None if v is None else _typed(inner, v)
    if tp is int:
        return int(v)
    if tp is float:
        return float(v)
    if tp is np.ndarray:
        return np.array(_infs(v), dtype=np.float64)
    if typing.get_origin(tp) is tuple:
        return tuple(_typed(args[0], x) for x in v)
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        return fields_from_dict(tp, v)
    raise TypeError(f"no rule for a field of type {tp!r}")


def _infs(v: Any) -> Any:
    if isinstance(v, list):
        return [_infs(x) for x in v]
    return np.inf if v is None else v
