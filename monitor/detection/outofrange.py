"""Which operating signal lay outside the model's trained range, by how much: what a user
needs from a "not judged" line (the signal, what the recording showed, what the model was
trained on) to know what data to add to the training."""

from __future__ import annotations

from typing import Any

import numpy as np

from monitor.model.envelope import Validity
from monitor.signals import UNITS


def out_of_range_values(values: np.ndarray, oor: np.ndarray, validity: Validity) -> dict[str, Any]:
    """Per signal named out of range (``oor``: index into ``validity.signals`` per sample,
    -1 for none; ``values`` the samples' values of those signals): samples, the range its
    out-of-range samples spanned and the trained range (the envelope, before the margin),
    in the signal's unit; the signal with the most samples first."""
    env = validity.envelope
    out: dict[str, Any] = {}
    if env is None:
        return out
    ks = [k for k in range(len(validity.signals)) if np.any(oor == k)]
    for k in sorted(ks, key=lambda k: -int(np.sum(oor == k))):
        name = validity.signals[k]
        v = values[oor == k, k]
        lo, hi = env.range_of(name)
        out[name] = {
            "samples": int(v.size),
            "min": round(float(np.min(v)), 3),
            "max": round(float(np.max(v)), 3),
            "trained_min": round(lo, 3),
            "trained_max": round(hi, 3),
            "unit": UNITS.get(name, ""),
        }
    return out


def describe(values: dict[str, Any]) -> str:
    """ "OilTemp 12.0-14.1 degC, trained 40.1-57.2 degC" for each signal, most samples first."""
    parts = []
    for name, d in values.items():
        unit = f" {d['unit']}" if d["unit"] else ""
        seen = f"{d['min']:.4g}" if d["min"] == d["max"] else f"{d['min']:.4g}-{d['max']:.4g}"
        parts.append(
            f"{name} {seen}{unit}, trained {d['trained_min']:.4g}-{d['trained_max']:.4g}{unit}"
        )
    return "; ".join(parts)
