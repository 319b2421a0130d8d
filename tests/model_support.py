"""Model files crafted from the shipped one: a header or arrays changed, the checksum made
valid again, so that a test reaches the loader's checks behind the checksum."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np

from monitor.model.modelfile import _checksum
from monitor.resources import resource_path

SHIPPED = resource_path("config", "boom_default.model.npz")


def craft_model(
    tmp_path: Path,
    header_change: Callable[[dict], None] | None = None,
    arrays_change: Callable[[dict], None] | None = None,
    raw_header: bytes | None = None,
    extra: dict | None = None,
) -> Path:
    """The shipped model with its header and arrays changed in place by the callables (or
    the header replaced by ``raw_header`` bytes, arrays ``extra`` added), checksum valid."""
    with np.load(SHIPPED, allow_pickle=False) as npz:
        data = {k: npz[k] for k in npz.files}
    header = json.loads(data["header"].tobytes())
    if header_change:
        header_change(header)
    hb = raw_header if raw_header is not None else json.dumps(header).encode()
    arrays = {k: v for k, v in data.items() if k not in ("header", "checksum")}
    if arrays_change:
        arrays_change(arrays)
    out = tmp_path / "crafted.npz"
    with out.open("wb") as fh:
        np.savez(
            fh,
            header=np.frombuffer(hb, np.uint8),
            checksum=np.frombuffer(_checksum(hb, arrays).encode(), np.uint8),
            **arrays,
            **(extra or {}),
        )
    return out


def set_key(key: str, value: object) -> Callable[[dict], None]:
    """A ``header_change`` that sets one header key."""

    def change(header: dict) -> None:
        header[key] = value

    return change
