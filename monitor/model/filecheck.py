"""Limits on a model file before anything trusts it: only the known arrays are read, their
unpacked size is bounded before unpacking, each has its dtype and rank, and every header value
the detector uses has its type and range (a NaN or infinite threshold would never alarm)."""

from __future__ import annotations

import math
import tokenize
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from monitor.model.npyheader import check_npz_headers

MAX_MODEL_BYTES = 512_000_000  # unpacked; a 20-minute commissioning model is a few MB
MAX_WINDOW_N = 360_000  # one hour of 100 Hz samples
# member -> (dtype, largest rank), as ``save_model`` writes them
LAYOUT: dict[str, tuple[str, int]] = {
    "header": ("u1", 1),
    "checksum": ("u1", 1),
    "patterns": ("f8", 2),
    "targets": ("f8", 2),
    "counts": ("f8", 1),
    "pattern_index": ("i8", 2),
    "isolation_centroids": ("f8", 2),
}


def read_members(path: Path) -> dict[str, np.ndarray]:
    """The known arrays of an ``.npz``; ValueError when too large or of the wrong kind."""
    with zipfile.ZipFile(path) as zf:
        sizes = {i.filename.removesuffix(".npy"): i.file_size for i in zf.infolist()}
    unpacked = sum(size for name, size in sizes.items() if name in LAYOUT)
    if unpacked > MAX_MODEL_BYTES:
        raise ValueError(f"its arrays unpack to {unpacked} bytes, more than {MAX_MODEL_BYTES}")
    try:
        check_npz_headers(path, LAYOUT)  # before np.load allocates what a header claims
        with np.load(path, allow_pickle=False) as npz:
            data = {k: npz[k] for k in npz.files if k in LAYOUT}
    except (SyntaxError, tokenize.TokenError) as exc:  # numpy parses .npy headers as Python
        raise ValueError(f"an array header is unreadable ({type(exc).__name__})") from None
    for name, a in data.items():
        dtype, rank = LAYOUT[name]
        if a.dtype != np.dtype(dtype) or a.ndim > rank:
            raise ValueError(
                f"array {name} is {a.dtype} of shape {a.shape}, expected {dtype} "
                f"of at most {rank} dimension(s)"
            )
    return data


def check_number(header: dict[str, Any], key: str, low: float, strict: bool) -> None:
    """ValueError unless ``header[key]`` is a finite number >= ``low`` (> when ``strict``)."""
    v = header.get(key)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ValueError(f"header {key} must be a finite number, got {str(v)[:40]}")
    if v < low or (strict and v == low):
        raise ValueError(f"header {key} must be {'>' if strict else '>='} {low:g}, got {v:g}")


def check_whole(section: dict[str, Any], key: str, low: int, high: int, prefix: str = "") -> None:
    """ValueError unless ``section[key]`` is a whole number in ``low..high`` (``prefix``: the
    section's name in the message, e.g. ``"hold."``)."""
    v = section.get(key)
    if isinstance(v, bool) or not isinstance(v, int) or not low <= v <= high:
        raise ValueError(f"header {prefix}{key} must be a whole number {low}..{high}")


def check_header(header: Any) -> None:
    """Types and ranges of the header values the detector relies on (ValueError)."""
    if not isinstance(header, dict):
        raise ValueError(f"the header is a JSON {type(header).__name__}, not an object")
    for key in ("spec", "normalizer", "threshold", "isolation"):
        if not isinstance(header.get(key), dict):
            raise ValueError(f"header {key} must be an object")
    check_number(header, "sigma", 0.0, strict=True)
    check_number(header["isolation"], "min_similarity", -1.0, strict=False)
    clip = header.get("residual_clip")
    if clip is not None and not (
        isinstance(clip, list)
        and all(
            not isinstance(c, bool) and isinstance(c, (int, float)) and math.isfinite(c) and c > 0
            for c in clip
        )
    ):
        raise ValueError("header residual_clip must be null or a list of finite numbers > 0")
    # The statistics (J's window and threshold, B's, L's, H's and any other member's
    # section): each member checks its own (``monitor.model.statistic``).
    from monitor.model.statistic import registry

    for stat in registry():
        stat.check_header(header)
