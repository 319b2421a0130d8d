"""Entrained air read at rest: a drained chamber that a leak cannot pressurise.

Air in the oil makes it soft near tank pressure and leaves it stiff at high pressure (free
air's volume goes as 1/p).  Held on an end stop with the spool centred, one chamber is
drained (near tank pressure) and the other loaded (some 200 bar).  Where oil leaks from
the loaded chamber into the drained one (across the piston seal, or through the valve's
centre), the same flow makes the loaded chamber's pressure fall at Q / C_loaded and the
drained one's rise at Q / C_drained: the ratio of the two rates is the ratio of the two
capacitances, C_loaded / C_drained.  With pure oil it is the ratio of their volumes: the
drained chamber on a stop is the small one, so it rises faster than the loaded one falls;
hoses add a capacitance to both and bring the two rates together.  With air the drained
chamber swallows the leak: at 1 bar absolute a 1 % air fraction is some 150 times softer
than the oil.

No simulation: the recording alone.  On the third plant written apart (seed 924107, and
development seed 1) the rise over the fall was 2.5-5.5 on healthy machines, 0.49-1.12 with
hose compliance, 0.05-0.32 with 0.5-2 % of air; the simulator (and the outsider's plant)
has no leak at rest, the loaded chamber holds its pressure and nothing is read.  There the
air's fit removed 3-17 % of a held-out gap this plant's base dynamics dominated, because the
simulator, with no leak at rest, cannot show the air's main effect there: a fill that
stalls.  The air fraction follows from the rates (isothermal free air, the configured
volumes and bulk modulus): 0.6-1.07 times the drawn fraction.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monitor.gap.data.prepare import Prepared
from monitor.gap.judge.decide import SIGNIFICANT
from monitor.gap.judge.shrink import finite_or_none, resamples
from monitor.signals import SAMPLE_PERIOD_S
from monitor.sim.machine import BAR, MachineParams

#: The catalogue effect this reads.
NAME = "entrained_air"
#: A hold read: spool within this of centre (% of stroke) for at least ``HOLD_S`` ...
CENTRED_PCT = 1.0
HOLD_S = 2.0
#: ... one chamber below ``DRAINED_BAR`` and the other above ``LOADED_BAR`` at its start;
#: the rates are read from ``FROM_S`` (the stop's ringing over) to ``HOLD_S``.
DRAINED_BAR = 3.0
LOADED_BAR = 100.0
FROM_S = 0.2
#: Least holds, and least fall (bar/s) of the loaded chamber (median): a leak to read ...
MIN_HOLDS = 5
MIN_FALL_BAR_S = 0.3
#: ... but not one that drains it elsewhere (a leaking check valve, A to tank: 67 bar/s;
#: the outsider's out-of-catalogue pressure-squared term: 37-39 bar/s; healthy machines
#: and air 1-3 bar/s): the drained chamber then does not receive what the loaded one
#: loses, and the ratio says nothing.
MAX_FALL_BAR_S = 10.0
#: A hold whose drained chamber reads at most this (bar) in half its samples or more is
#: not read: a pressure sensor clipping at its zero (an offset of -9.5 bar) hides the rise.
ZERO_BAR = 0.05
#: The drained chamber rising less than this times as fast as the loaded one falls is
#: air.  Pure oil or hoses: the smaller, drained chamber rises faster (2.5 and more
#: healthy; hoses 0.49-1.12, the 0.49 below the level in 12 % of its resamples); air
#: 0.05-0.32.
RATIO = 0.45
P_ATM_PA = 101325.0


@dataclass(frozen=True)
class AirSignature:
    """What the drained chambers on the end stops say about the oil's stiffness."""

    holds: int
    #: Medians over the holds: the drained chamber's rise and the loaded one's fall
    #: (bar/s), and the drained chamber's mean pressure (bar).
    rise_bar_s: float
    fall_bar_s: float
    drained_bar: float
    #: rise / fall, and the share of bootstrap resamples (of the holds) with it below
    #: ``RATIO``.
    ratio: float
    below_share: float
    #: Air per oil volume at atmospheric pressure that makes the drained chamber as soft
    #: as it reads (isothermal free air; NaN: not read).
    air_fraction: float

    @property
    def readable(self) -> bool:
        return self.holds >= MIN_HOLDS and MIN_FALL_BAR_S <= self.fall_bar_s <= MAX_FALL_BAR_S

    @property
    def present(self) -> bool:
        return self.readable and self.below_share >= SIGNIFICANT

    def evidence(self) -> str:
        if not self.readable:
            return (
                f"no leak to read the drained chambers by ({self.holds} holds on a stop with "
                f"one chamber drained, the loaded one falling {_f(self.fall_bar_s)} bar/s; "
                f"{MIN_HOLDS} and {MIN_FALL_BAR_S:g}-{MAX_FALL_BAR_S:g} bar/s needed)"
            )
        return (
            f"held on the end stops ({self.holds} holds), the drained chamber rises "
            f"{self.rise_bar_s:.2f} bar/s at {self.drained_bar:.1f} bar while the loaded one "
            f"falls {self.fall_bar_s:.2f} bar/s: {self.ratio:.2f} times (below {RATIO:g} in "
            f"{100 * self.below_share:.0f} % of the resamples); soft near tank pressure, "
            f"stiff at high pressure, as {100 * self.air_fraction:.1f} % of free air"
        )

    def as_dict(self) -> dict:
        return {
            "holds": self.holds,
            "rise_bar_s": finite_or_none(self.rise_bar_s, 3),
            "fall_bar_s": finite_or_none(self.fall_bar_s, 3),
            "drained_bar": finite_or_none(self.drained_bar, 2),
            "ratio": finite_or_none(self.ratio, 3),
            "ratio_level": RATIO,
            "below_share": round(self.below_share, 3),
            "air_fraction": finite_or_none(self.air_fraction, 4),
            "readable": self.readable,
            "present": self.present,
            "evidence": self.evidence(),
        }


def holds(prep: Prepared, machine: MachineParams) -> np.ndarray:
    """Per hold on a stop with one chamber drained: [rise bar/s, fall bar/s, drained bar,
    drained volume m^3, loaded volume m^3]."""
    centred = prep.valid & (np.abs(prep.cmd["SpoolCmd"]) < CENTRED_PCT)
    need, start = round(HOLD_S / SAMPLE_PERIOD_S), round(FROM_S / SAMPLE_PERIOD_S)
    edges = np.flatnonzero(np.diff(centred.astype(np.int8)) == 1) + 1
    cyl = machine.cylinder
    rows = []
    for k in edges:
        r = np.arange(k, min(k + need, len(centred)))
        if len(r) < need or not centred[r].all():
            continue
        pa, pb = prep.meas["PA"][r], prep.meas["PB"][r]
        a_low = pa[0] < pb[0]
        low, high = (pa, pb) if a_low else (pb, pa)
        if not (low[0] < DRAINED_BAR and high[0] > LOADED_BAR) or not np.isfinite(low + high).all():
            continue
        if np.mean(low <= ZERO_BAR) >= 0.5:
            continue
        span = (need - start) * SAMPLE_PERIOD_S
        rise = (low[-5:].mean() - low[start : start + 5].mean()) / span
        fall = (high[start : start + 5].mean() - high[-5:].mean()) / span
        x = float(np.clip(prep.rod_mm[k], 0.0, prep.stroke_mm)) * 1e-3
        v_a = cyl.dead_volume_a_m3 + cyl.area_a_m2 * x
        v_b = cyl.dead_volume_b_m3 + cyl.area_b_m2 * (cyl.stroke_m - x)
        vols = (v_a, v_b) if a_low else (v_b, v_a)
        rows.append((rise, fall, float(low[start:].mean()), *vols))
    return np.array(rows).reshape(-1, 5)


def signature(prep: Prepared, machine: MachineParams) -> AirSignature:
    """The drained chambers' stiffness against the loaded ones'."""
    h = holds(prep, machine)
    nan = float("nan")
    if len(h) == 0:
        return AirSignature(0, nan, nan, nan, nan, 0.0, nan)
    rise, fall = float(np.median(h[:, 0])), float(np.median(h[:, 1]))
    ratio = rise / fall if fall > 0 else nan
    boot = []
    for b in resamples(len(h), seed=3):
        f = np.median(h[b, 1])
        boot.append(np.median(h[b, 0]) / f if f > 0 else np.inf)
    below = float(np.mean(np.array(boot) < RATIO))
    return AirSignature(
        holds=len(h),
        rise_bar_s=rise,
        fall_bar_s=fall,
        drained_bar=float(np.median(h[:, 2])),
        ratio=ratio,
        below_share=below,
        air_fraction=_fraction(h, machine.oil.bulk_modulus_pa),
    )


def _fraction(h: np.ndarray, beta_pa: float) -> float:
    """The isothermal free-air fraction at atmosphere that gives the drained chamber the
    softness the rates show: the leak is the loaded chamber's oil capacitance times its
    fall; the drained chamber's capacitance is that leak over its rise, V/beta of it oil
    and a V p0 / p^2 of it air (p absolute)."""
    rise, fall = h[:, 0] * BAR, h[:, 1] * BAR
    ok = rise > 0
    if not ok.any():
        return float("nan")
    leak = h[ok, 4] / beta_pa * fall[ok]
    soft = leak / rise[ok] - h[ok, 3] / beta_pa
    p_abs = h[ok, 2] * BAR + P_ATM_PA
    return float(np.median(np.maximum(soft, 0.0) * p_abs**2 / (h[ok, 3] * P_ATM_PA)))


def _f(v: float) -> str:
    return f"{v:.2f}" if np.isfinite(v) else "-"
