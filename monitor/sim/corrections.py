"""Data-driven corrections: terms of a small library of physical shapes that the
sim-to-real tool adds to the simulator when no catalogue effect explains a gap
(``monitor gap``'s ``suggestion``).

Each correction is one kernel parameter (indices 50-69 of ``kernel.py``), SI, zero in the
nominal model.  A zero value leaves the simulation bit-identical.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from monitor.sim import kernel as K

#: Correction name -> (kernel index, SI unit).
CORRECTIONS: dict[str, tuple[int, str]] = {
    "leak_pt_lin": (K.LEAK_PT_LIN, "m^3/s per Pa"),
    "leak_pt_sqrt": (K.LEAK_PT_SQRT, "m^3/s per sqrt(Pa)"),
    "leak_at_lin": (K.LEAK_AT_LIN, "m^3/s per Pa"),
    "leak_at_sqrt": (K.LEAK_AT_SQRT, "m^3/s per sqrt(Pa)"),
    "leak_at_sq": (K.LEAK_AT_SQ, "m^3/s per Pa^2"),
    "leak_bt_lin": (K.LEAK_BT_LIN, "m^3/s per Pa"),
    "leak_bt_sqrt": (K.LEAK_BT_SQRT, "m^3/s per sqrt(Pa)"),
    "leak_ab_lin": (K.LEAK_AB_LIN, "m^3/s per Pa"),
    "leak_ab_sqrt": (K.LEAK_AB_SQRT, "m^3/s per sqrt(Pa)"),
    "force_velocity": (K.F_VEL, "N s/m"),
    "force_sign": (K.F_SIGN, "N"),
    "force_position": (K.F_POS, "N/m"),
    "force_cos": (K.F_PER_COS, "N"),
    "force_sin": (K.F_PER_SIN, "N"),
    "force_omega": (K.F_PER_W, "rad/s"),
    "kv_pa_rel": (K.KV_PA_REL, "-"),
    "kv_pb_rel": (K.KV_PB_REL, "-"),
    "kv_at_rel": (K.KV_AT_REL, "-"),
    "kv_bt_rel": (K.KV_BT_REL, "-"),
}


def pack_corrections(prm: np.ndarray, corrections: Mapping[str, float]) -> None:
    """Write ``corrections`` (name: SI value) into the kernel parameter vector ``prm``."""
    unknown = set(corrections) - set(CORRECTIONS)
    if unknown:
        raise ValueError(f"unknown corrections: {', '.join(sorted(unknown))}")
    for name, value in corrections.items():
        prm[CORRECTIONS[name][0]] = float(value)
    # The kernel skips the whole block unless one term is non-zero (a frequency alone
    # changes nothing).
    active = any(v != 0.0 for n, v in corrections.items() if n != "force_omega")
    prm[K.CORR_ON] = 1.0 if active else 0.0
