"""Cause second: a leak the fits put down to oil viscosity is checked against the oil
temperature.  A leak that follows the temperature (thin oil leaks more) is viscosity; one
that does not is wear (a worn pump, a scored seal), which the catalogue does not hold.

The check refits the named leak with an oil whose viscosity does not change with
temperature (the same paths and knobs, ``FLAT_OIL``) and compares the two on the held-out
part under the block bootstrap, like an effect against the simulator it must beat.  It
needs the oil temperature to move: over a warm-up from 20 to 55 degC an ISO VG 46 oil
thins by a factor of five, so the two laws part by far more than the noise; on a warm
machine whose oil stays within a few degrees they are one law.  There what else a thinner
oil changes decides, where the recording shows it: the rod's viscous friction falls with
the viscosity, a worn pump leaves it alone (``judge/thinoil.py``).  Otherwise the verdict
says which recording would tell the causes apart.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from monitor.gap.diagnose.evaluate import Evaluator, score
from monitor.gap.diagnose.records import Calibrated, Parts, Scores
from monitor.gap.fit import score as S
from monitor.gap.fit.candidates import Candidate, Member, default_member, fit_candidate
from monitor.gap.judge import thinoil
from monitor.gap.judge.decide import SIGNIFICANT, Decision, gain_share
from monitor.gap.judge.leakratio import LeakRatio, leak_ratio
from monitor.gap.judge.where import scored_mask
from monitor.sim.pack import viscosity_cst

Progress = Callable[[str], None]

NAME = "oil_viscosity"
#: An oil whose viscosity does not follow the temperature (Walther through 20 and 19.99 cSt:
#: within 0.03 % of its 40 degC value from 10 to 70 degC): the same leak, constant.
FLAT_OIL: tuple[tuple[str, float], ...] = (("nu40_cst", 20.0), ("nu100_cst", 19.99))
#: Oil temperature span (5th to 95th percentile of the compared samples, degC) below which
#: the recording cannot tell the causes apart: 10 degC thins an ISO VG 46 oil by about a
#: third near 40 degC, a leak change of the order of the fits' own spread.
MIN_SPAN_C = 10.0
#: The leak paths of the family's knobs, as the suggestion's ``signal`` names them.
PATHS = {
    "pump_leak_lpm_per_100bar": ("pump leakage", "P->tank"),
    "piston_leak_lpm_per_100bar": ("leakage across the piston seal", "A<->B"),
    "valve_leak_lpm_per_100bar": ("leakage across the valve clearances", "A->tank"),
}


@dataclass(frozen=True)
class LeakCause:
    """The oil-temperature check of a leak named ``oil_viscosity``."""

    #: The leak path that carries most of the fitted leak (a ``PATHS`` key).
    path: str
    span_c: float
    #: The leak as named, following the viscosity.
    viscous: Candidate
    #: The temperature-flat leak refitted and scored (None: the span was too small).
    flat: Candidate | None = None
    #: Share of bootstrap resamples in which the flat leak has the smaller held-out gap.
    flat_share: float | None = None
    #: The oil temperature's 5th and 95th percentiles over the scored samples (degC).
    temps_c: tuple[float, float] | None = None
    #: Where the span was too small: the rod's viscous friction against what the
    #: configured oil allows (``judge/thinoil.py``; None: not read).
    oil: thinoil.ThinOil | None = None
    #: The constant leak refitted on the cold and the warm third of the segments, against
    #: the ratio viscosity predicts (``judge/leakratio.py``; None: too few segments).
    thirds: LeakRatio | None = None

    def _nu_cst(self) -> np.ndarray | None:
        """The named oil's viscosity at the cold and the warm end (cSt)."""
        if self.temps_c is None:
            return None
        p = self.viscous.effects[0].params
        return viscosity_cst(np.asarray(self.temps_c), p["nu40_cst"], p["nu100_cst"])

    @property
    def viscosity_ratio(self) -> float | None:
        """How many times thicker the named oil is at the cold end of the recording than
        at its warm end: how far a laminar leak (~ 1/viscosity) grows over the recording."""
        nu = self._nu_cst()
        return None if nu is None else float(nu[0] / nu[1])

    def viscous_leak(self) -> tuple[float, float] | None:
        """The named leak (L/min per 100 bar) at the cold and the warm end, as the
        viscosity law puts it: its 40 degC value times nu40 / nu(T)."""
        nu = self._nu_cst()
        if nu is None:
            return None
        p = self.viscous.effects[0].params
        cold, warm = float(p[self.path]) * p["nu40_cst"] / nu
        return float(cold), float(warm)

    @property
    def cause(self) -> str | None:
        """``oil_viscosity`` or ``wear``; None: the recording cannot tell."""
        if self.flat_share is None:
            return NAME if self.oil is not None and self.oil.thin else None
        if self.thirds is not None:
            return self.thirds.cause
        if self.flat_share >= SIGNIFICANT:
            return "wear"
        if self.flat_share <= 1.0 - SIGNIFICANT:
            return NAME
        return None

    def as_dict(self) -> dict:
        """The JSON's ``cause_check``."""
        mechanism, signal = PATHS[self.path]
        out: dict = {
            "mechanism": mechanism,
            "signal": signal,
            "oil_temp_span_c": round(self.span_c, 1),
            "cause": self.cause,
            "viscous_heldout_reduction": round(float(self.viscous.heldout_reduction), 4),
        }
        if self.flat is not None and self.flat_share is not None:
            out["flat_heldout_reduction"] = round(float(self.flat.heldout_reduction), 4)
            out["flat_better_share"] = round(self.flat_share, 3)
            out["flat_leak_lpm_per_100bar"] = round(self.flat.effects[0].params[self.path], 4)
        if self.thirds is not None:
            out["thirds"] = self.thirds.as_dict()
        if self.oil is not None:
            out["oil_friction"] = self.oil.as_dict()
            out["decided_by"] = "rod friction" if self.oil.thin else None
        elif self.cause is not None:
            out["decided_by"] = "oil temperature"
        if self.temps_c is not None:
            out["oil_temp_c"] = [round(t, 1) for t in self.temps_c]
            out["viscosity_ratio"] = round(float(self.viscosity_ratio or 1.0), 3)
            out["viscous_leak_cold_warm_lpm_per_100bar"] = [
                round(v, 4) for v in self.viscous_leak() or ()
            ]
        out["evidence"] = self.evidence()
        out["causes"] = self.causes()
        return out

    def causes(self) -> list[dict]:
        """The two causes of the leak, each with its law, its held-out reduction and what
        the check made of it: ``kept``, ``rejected`` or ``undecided``."""
        cause = self.cause
        laws = (
            (NAME, "leak ~ 1/viscosity (laminar)", self.viscous),
            ("wear", "leak constant in oil temperature", self.flat),
        )
        out = []
        for name, law, c in laws:
            status = "undecided" if cause is None else "kept" if cause == name else "rejected"
            out.append(
                {
                    "cause": name,
                    "law": law,
                    "heldout_reduction": None
                    if c is None
                    else round(float(c.heldout_reduction), 4),
                    "status": status,
                }
            )
        return out

    def _swing(self) -> str:
        """The leak a viscosity law would show over the recording, in words."""
        leak, r = self.viscous_leak(), self.viscosity_ratio
        if leak is None or r is None or self.temps_c is None:
            return ""
        lo, hi = self.temps_c
        return (
            f" (from {lo:.0f} to {hi:.0f} degC the oil thins {r:.1f}-fold: a leak following "
            f"1/viscosity goes from {leak[0]:.2g} to {leak[1]:.2g} L/min per 100 bar)"
        )

    def evidence(self) -> str:
        """One line: what decided, or which recording would."""
        if self.flat_share is None and self.cause == NAME:
            assert self.oil is not None
            return (
                f"the oil temperature spans {self.span_c:.0f} degC, too little to follow the "
                f"leak through it, but {self.oil.evidence()}: the oil explains the leak and "
                "the friction together, a worn pump the leak only"
            )
        if self.flat_share is None:
            rod = f" ({self.oil.evidence()})" if self.oil is not None else ""
            return (
                f"the oil temperature spans {self.span_c:.0f} degC: a leak that follows it "
                f"(viscosity) and one that does not (wear) look alike{rod}; a warm-up run (oil "
                "from about 20 to 50 degC) would tell them apart"
            )
        pct, swing = 100 * self.flat_share, self._swing()
        if self.thirds is not None:
            t = self.thirds
            grew = t.above_one >= SIGNIFICANT
            verdict = {
                "wear": "it does not follow the viscosity (wear, not viscosity"
                + ("; it grew, but nearer a worn pump's 1" if grew else "")
                + ")",
                NAME: "it follows the viscosity (viscosity, not wear)",
                None: "the two causes are not told apart: a longer warm-up would tell them apart",
            }[self.cause]
            return (
                f"over {self.span_c:.0f} degC of oil temperature, {t.evidence()}: {verdict}; "
                f"over the whole recording a constant leak fits the held-out part better in "
                f"{pct:.0f} % of resamples"
            )
        if self.cause == "wear":
            flat = self.flat.effects[0].params[self.path] if self.flat is not None else 0.0
            return (
                f"over {self.span_c:.0f} degC of oil temperature the leak does not follow "
                f"the viscosity{swing}: a constant leak ({flat:.2g} L/min per 100 bar) fits "
                f"the held-out part better in {pct:.0f} % of resamples (wear, not viscosity)"
            )
        if self.cause == NAME:
            return (
                f"over {self.span_c:.0f} degC of oil temperature the leak follows the "
                f"viscosity{swing}: a constant leak fits the held-out part better in only "
                f"{pct:.0f} % of resamples"
            )
        return (
            f"over {self.span_c:.0f} degC of oil temperature a leak that follows the viscosity "
            f"and a constant one fit alike{swing} (the constant one better in {pct:.0f} % of "
            "resamples): a longer warm-up would tell them apart"
        )


def oil_range_c(parts: Parts) -> tuple[float, float] | None:
    """The oil temperature's 5th and 95th percentiles over the scored samples (degC)."""
    prep = parts.prep
    temp = prep.cmd["OilTemp"][scored_mask(len(prep), parts.segments)]
    temp = temp[np.isfinite(temp)]
    if not temp.size:
        return None
    return float(np.percentile(temp, 5)), float(np.percentile(temp, 95))


def oil_span_c(parts: Parts) -> float:
    """The oil temperature's 5th-95th percentile span over the scored samples (degC)."""
    temps = oil_range_c(parts)
    return temps[1] - temps[0] if temps is not None else 0.0


def main_path(c: Candidate) -> str:
    """The leak path with the largest fitted leak."""
    p = c.effects[0].params
    return max(PATHS, key=lambda k: float(p.get(k, 0.0)))


def flat_member(m: Member) -> Member:
    """``m`` with a temperature-flat oil (same knobs, same paths)."""
    fixed = tuple(kv for kv in m.fixed if kv[0] not in dict(FLAT_OIL)) + FLAT_OIL
    return replace(m, name=f"{m.name}_constant", fixed=fixed, starts=())


def check_leak(
    parts: Parts, cal: Calibrated, scores: Scores, boot_idx: np.ndarray, chosen: Candidate
) -> LeakCause:
    """The named ``oil_viscosity`` single ``chosen`` against the same leak with a flat oil,
    both with ``chosen``'s tolerances (one local fit and one held-out run)."""
    temps, path = oil_range_c(parts), main_path(chosen)
    span = temps[1] - temps[0] if temps is not None else 0.0
    if span < MIN_SPAN_C:
        oil = thinoil.signature(cal.readings.prep, parts.segments, cal.fit_machine)
        return LeakCause(path, span, chosen, temps_c=temps, oil=oil)
    member = chosen.members[0] if chosen.members else default_member(NAME)
    flat_m = flat_member(member)
    residual = cal.readings.fit(chosen.prep).residual
    starts = [(chosen.factors, chosen.effects)]
    flat = fit_candidate([NAME], residual, chosen.factors, (), starts, members=[flat_m])
    flat = replace(flat, prep=chosen.prep)
    base = scores.baseline
    sums = cal.readings.held(chosen.prep).sums(flat.factors, flat.effects)
    score(flat, sums, cal.floor, base.gap0, base.n_eff)
    viscous_sums = cal.readings.held(chosen.prep).sums(chosen.factors, chosen.effects)
    share = gain_share(viscous_sums, sums, boot_idx, cal.floor)
    thirds = thirds_check(parts, cal, chosen, flat, path)
    return LeakCause(path, span, chosen, flat, share, temps, thirds=thirds)


def thirds_check(
    parts: Parts, cal: Calibrated, chosen: Candidate, flat: Candidate, path: str
) -> LeakRatio | None:
    """The constant leak's level on the cold and the warm third of all the segments (fit
    and held-out), at the flat fit's tolerances, against the viscous ratio of the named oil
    (two simulations of the segments: at the flat leak and a fifth above it)."""
    prep = chosen.prep if chosen.prep is not None else cal.readings.prep
    segs = [s for s in parts.segments if s.scored.stop > s.scored.start]
    temps = np.array([np.nanmean(prep.cmd["OilTemp"][s.scored]) for s in segs])
    ok = np.isfinite(temps)
    segs, temps = [s for s, k in zip(segs, ok, strict=True) if k], temps[ok]
    if len(segs) < 3:
        return None
    ev = Evaluator(prep, segs, cal.fit_machine)
    effect = flat.effects[0]
    leak0 = float(effect.params[path])
    step = 0.2 * max(leak0, 0.1)

    def residuals(leak: float) -> list[np.ndarray]:
        e = replace(effect, params={**effect.params, path: leak})
        r = S.normalised(prep, ev.predict(flat.factors, (e,)))
        return [np.nan_to_num(np.concatenate([r[n][s.scored] for n in r])) for s in segs]

    r0, r1 = residuals(leak0), residuals(leak0 + step)
    jac = [(x1 - x0) / step for x0, x1 in zip(r0, r1, strict=True)]
    a = np.array([float(j @ j) for j in jac])
    b = np.array([float(j @ x0) for j, x0 in zip(jac, r0, strict=True)])
    p = chosen.effects[0].params
    inv_nu = 1.0 / viscosity_cst(temps, p["nu40_cst"], p["nu100_cst"])
    return leak_ratio(a, b, temps, inv_nu, leak0)


def judge_cause(
    d: Decision, parts: Parts, cal: Calibrated, scores: Scores, boot_idx: np.ndarray, say: Progress
) -> tuple[Decision, LeakCause | None]:
    """An ``oil_viscosity`` verdict (alone or with a second effect) checked against the oil
    temperature, on the single effect's leak: a leak that does not follow it is wear, out
    of the catalogue (``unexplained``, the leak first in the suggestion); otherwise the
    verdict stands, with the check."""
    if d.verdict != NAME:
        return d, None
    # A pair's leak (oil_viscosity also sensor_lag: a worn pump on the third plant) is
    # checked as the single effect: the law of the leak is what is in question.
    c = next((s for s in scores.singles if s.name == NAME), None)
    if c is None:
        return d, None
    chk = check_leak(parts, cal, scores, boot_idx, c)
    say(f"oil_viscosity against the oil temperature: {chk.evidence()}")
    if chk.cause == "wear":
        sure = chk.thirds.below_viscous if chk.thirds is not None else chk.flat_share
        return Decision("unexplained", None, None, float(sure or 0.0)), chk
    if chk.cause is None:
        # The mechanism is decided (the leak removes the gap), its cause is not: a verdict
        # names no cause its evidence did not decide.  ``unexplained`` with the leak first
        # in the suggestion (cause undecided) and the recording that would decide; the
        # confidence is the leak's, as the mechanism is as sure as the effect was.
        return Decision("unexplained", None, None, d.confidence), chk
    return d, chk


def suggestion_entry(chk: LeakCause) -> dict:
    """The leak as the suggestion's first term (the contract's object) when its cause is
    wear (the constant leak) or undecided (the better-scoring of the two laws' leaks, at the
    recording's oil temperature)."""
    mechanism, signal = PATHS[chk.path]
    fits = [c for c in (chk.viscous, chk.flat) if c is not None]
    if chk.cause == "wear":
        assert chk.flat is not None
        fits = [chk.flat]
    best = max(fits, key=lambda c: float(c.heldout_reduction))
    if best is chk.flat:
        leak = float(best.effects[0].params[chk.path])
    else:  # the viscous law's leak at the recording's mean oil temperature
        ends = chk.viscous_leak()
        leak = float(np.mean(ends)) if ends else float(best.effects[0].params[chk.path])
    if chk.cause == "wear":
        text = f"{mechanism} that does not follow the oil temperature (wear)"
    else:
        text = (
            f"{mechanism}, cause undecided (oil viscosity or wear; a warm-up run over a wider "
            "oil temperature span would decide)"
        )
    return {
        "term": "leakage",
        "signal": signal,
        "shape": "dp",
        "description": f"{text}: {leak:.3g} L/min per 100 bar",
        "coefficient": round(leak, 6),
        "unit": "L/min per 100 bar",
        "heldout_reduction": round(float(best.heldout_reduction), 4),
        "cause": chk.cause or "undecided",
    }
