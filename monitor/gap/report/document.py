"""The diagnosis as the contract JSON (the one-page text summary: ``summary.py``).

JSON keys (issue 6, other tools read them): ``verdict``, ``also``, ``params``,
``calibrated``, ``confidence``, ``where`` {signals, regimes, bands, windows}, ``ranking``,
``shrink`` {before, after, heldout_reduction}; extra keys add detail without changing those.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from monitor.gap.data.prepare import Prepared
from monitor.gap.diagnose.records import Absorbed, Diagnosis, Finding
from monitor.gap.fit import calibrate as cal_mod
from monitor.gap.fit import sensorcal
from monitor.gap.fit.candidates import Candidate, default_member
from monitor.gap.fit.score import SegmentSums, compared, gap, normalised, reduction
from monitor.gap.judge import basemis, delays, mechanism
from monitor.gap.judge import where as W
from monitor.gap.judge.shrink import shrink_report
from monitor.gap.report.bounds import calibration_bounds
from monitor.signals import MEASURED_NAMES
from monitor.sim.effects import CATALOGUE, Effect
from monitor.sim.machine import MachineParams


def _rodpos(prep: Prepared, chosen: Candidate | None) -> str:
    """Where the rod path came from: the recording's ``recording.rodpos``."""
    if prep.has_rodpos:
        return "measured"
    if chosen is not None and chosen.prep is not None:  # ``reread.py``
        return "integrated from QP read through the fitted QP calibration"
    return "integrated from QP"


def effect_params(effect: Effect, fitted: set[str] | None = None) -> dict[str, dict]:
    """Values keyed by the effect's ``--effect`` parameter names, with units; ``fitted``
    names the fitted ones (default: those of the effect's default formulation).

    ``sensor_calibration`` is keyed by the signal instead (``PA_gain``, ``PA_offset_bar``:
    the contract's names), with the same plain values under ``sensor_calibration``."""
    if effect.name == sensorcal.NAME:
        keys = sensorcal.report_keys(effect)
        out: dict[str, dict] = {
            k: {"value": round(float(v), 6), "unit": unit, "fitted": True}
            for k, (v, unit) in keys.items()
        }
        out[effect.name] = {k: round(float(v), 6) for k, (v, _) in keys.items()}
        return out
    if effect.name == "sensor_lag" and effect.labels.get("signal"):
        # A lag on some readings only (``diagnose/timing.py``): which, beside the values.
        lagged = {k: round(float(v), 6) for k, v in effect.params.items()}
        late = {"signals": effect.labels["signal"].split(","), **lagged}
        # The delay is the late readings' measured one; the time constant is not fitted.
        return {**effect_params(replace(effect, labels={}), {"delay_ms"}), "sensor_lag": late}
    if fitted is None:
        fitted = {k.name for k in default_member(effect.name).knobs}
    if effect.name == "cylinder_friction":
        fitted.add("static_n")
    spec = CATALOGUE[effect.name]
    return {
        p.name: {
            "value": round(float(effect.params[p.name]), 6),
            "unit": p.unit,
            "fitted": p.name in fitted,
        }
        for p in spec.params
    }


def member_names(c: Candidate) -> dict[str, str]:
    """Which formulation of each effect's family fitted (``default`` for one-member ones)."""
    members = c.members or tuple(default_member(e.name) for e in c.effects)
    return {e.name: m.name for e, m in zip(c.effects, members, strict=True)}


def _candidate_row(c: Candidate) -> dict:
    return {
        "effect": c.name,
        "heldout_reduction": round(float(c.heldout_reduction), 4),
        "criterion": round(float(c.criterion), 2),
        "params": {e.name: _plain_params(e) for e in c.effects},
        "members": member_names(c),
    }


def _fitted(member) -> set[str]:
    return {k.name for k in member.knobs}


def _plain_params(e: Effect) -> dict[str, float]:
    if e.name == sensorcal.NAME:
        return {k: round(float(v), 6) for k, (v, _) in sensorcal.report_keys(e).items()}
    return {k: round(v, 6) for k, v in e.params.items()}


def _regime_shrink(diag: Diagnosis, held_mask: np.ndarray) -> list[dict]:
    prep, traces = diag.parts.prep, diag.traces
    r0 = normalised(prep, traces.nominal)
    r1 = normalised(prep, traces.corrected) if traces.corrected is not None else r0
    rows = []
    for name, rmask in W.regimes(prep).items():
        m = rmask & held_mask
        if m.sum() < W.MIN_REGIME_SHARE * held_mask.sum():
            continue

        def nrmse(r: dict[str, np.ndarray], m: np.ndarray = m) -> float:
            return float(np.sqrt(np.mean([np.nanmean(r[n][m] ** 2) for n in MEASURED_NAMES])))

        rows.append({"regime": name, "before": round(nrmse(r0), 5), "after": round(nrmse(r1), 5)})
    return rows


def _named_params(finding: Finding) -> dict:
    """The JSON's ``params``, ``also_params``, ``member`` and ``also_member``: the named
    effects' fitted values and which formulation of each family fitted."""
    chosen = finding.chosen
    out: dict = {"params": {}, "also_params": None, "member": None, "also_member": None}
    if chosen is None:
        return out
    by_name = {e.name: e for e in chosen.effects}
    mem = dict(zip(by_name, chosen.members or map(default_member, by_name), strict=True))
    out["params"] = effect_params(by_name[finding.verdict], _fitted(mem[finding.verdict]))
    out["member"] = mem[finding.verdict].name
    if finding.also is not None:
        out["also_params"] = effect_params(by_name[finding.also], _fitted(mem[finding.also]))
        out["also_member"] = mem[finding.also].name
    return out


def _where(diag: Diagnosis) -> dict:
    """The JSON's ``where``: the calibrated nominal simulator's residual, all segments."""
    prep = diag.parts.prep
    all_mask = W.scored_mask(len(prep), diag.parts.segments)
    resid = normalised(prep, diag.traces.nominal)
    return {
        "signals": W.by_signal(resid, all_mask),
        "regimes": W.by_regime(prep, resid, all_mask),
        "bands": W.by_band(prep, resid),
        "windows": W.worst_windows(prep, resid, all_mask),
    }


def _recording(diag: Diagnosis) -> dict:
    """The JSON's ``recording``: what was diagnosed and how it was split."""
    prep, parts = diag.parts.prep, diag.parts
    return {
        "source": prep.source,
        "duration_s": round(float(prep.t[-1] - prep.t[0]), 2),
        "rodpos": _rodpos(prep, diag.finding.chosen),
        "segments": len(parts.segments),
        "calibration_s": round(sum(s.duration_s() for s in parts.calibration), 1),
        "heldout_s": round(sum(s.duration_s() for s in parts.heldout), 1),
    }


def _checks(diag: Diagnosis) -> dict:
    """The optional keys: ``suggestion`` (for ``unexplained``), ``sensor_check``,
    ``trade_off``, ``lag_check`` and ``absorbed``, each present only when it says something."""
    f, tol = diag.finding, diag.tolerances
    return {
        **(
            {"suggestion": f.suggestion, "suggestion_tried": f.suggestion_tried}
            if f.verdict == "unexplained"
            else {}
        ),
        **({"sensor_check": f.sensor_check} if f.sensor_check is not None else {}),
        **({"trade_off": f.traded} if f.traded is not None else {}),
        **({"lag_check": f.lag_check} if f.lag_check is not None else {}),
        **({"cause_check": f.cause_check} if f.cause_check is not None else {}),
        **({"timing_check": f.timing_check} if f.timing_check is not None else {}),
        **({"friction_check": f.friction_check} if f.friction_check is not None else {}),
        **({"timing": f.timing} if f.timing is not None else {}),
        **({"load_check": f.load_check} if f.load_check is not None else {}),
        **({"air_check": f.air_check} if f.air_check is not None else {}),
        **({"slip_check": f.slip_check} if f.slip_check is not None else {}),
        **({"metering_check": diag.metering_check} if diag.metering_check else {}),
        **_absorbed(f.chosen, diag.ranking.absorbed, tol.floor),
    }


def build_report(diag: Diagnosis, machine: MachineParams) -> dict:
    """The JSON document (plain types only): what ``diag`` holds, rendered."""
    prep, tol, rank, f = diag.parts.prep, diag.tolerances, diag.ranking, diag.finding
    held_mask = W.scored_mask(len(prep), diag.parts.heldout)
    chosen = f.chosen
    after = rank.sums[chosen.name] if chosen is not None else tol.nominal
    regimes = _regime_shrink(diag, held_mask)
    shrink = shrink_report(tol.nominal, after, rank.boot_idx, tol.floor, regimes, compared(prep))
    named = _named_params(f)
    report = {
        "verdict": f.verdict,
        "also": f.also,
        "params": named["params"],
        "also_params": named["also_params"],
        # Which formulation of the effect's family fitted (issue 18; "default" for effects
        # with one formulation).
        "member": named["member"],
        "also_member": named["also_member"],
        "calibrated": cal_mod.describe(machine, chosen.factors if chosen else tol.factors),
        "confidence": round(float(f.confidence), 3),
        "where": _where(diag),
        "ranking": [_candidate_row(c) for c in rank.singles],
        "pairs": [_candidate_row(c) for c in rank.pairs],
        "shrink": shrink,
        "base_mismatch": _base_mismatch(diag, compared(prep), after, chosen),
        "recording": _recording(diag),
        "timings_s": {k: round(v, 2) for k, v in diag.timings_s.items()},
        "identifiability": diag.identifiability,
        # A tolerance the calibration left at its bound, and the candidates it could hide.
        "calibration_bounds": calibration_bounds(diag),
        # Per signal: how late the reading is against the calibrated simulator (held out).
        "delays_ms": delays.delays_ms(prep, diag.parts.heldout, diag.traces.nominal),
        **_checks(diag),
    }
    # Mechanism first, cause second: read from the keys above (``judge/mechanism.py``).
    report["mechanism"] = mechanism.describe(report)
    return report


def _absorbed(chosen: Candidate | None, absorbed: dict[str, Absorbed], floor: np.ndarray) -> dict:
    """The JSON ``absorbed``: the named effect's tolerances that the calibration had taken
    to their bound in its place (``diagnose.calibration_absorbed``), and the share of the
    held-out gap of its own tolerances without it that the effect removes (what it was
    judged on)."""
    # Keyed by single effects: a pair or no verdict has none.
    a = absorbed.get(chosen.name) if chosen is not None else None
    if chosen is None or a is None:
        return {}
    without = gap(a.sums[0].mse(), floor)
    return {
        "absorbed": {
            "effect": chosen.effects[0].name,
            "tolerances": {
                t: {
                    "calibration_pct": round(100 * (f0 - 1), 2),
                    "with_effect_pct": round(100 * (f1 - 1), 2),
                }
                for t, (f0, f1) in a.tolerances.items()
            },
            "heldout_reduction": round(reduction(without, chosen.heldout_gap), 4),
        }
    }


def _base_mismatch(
    diag: Diagnosis, names: Sequence[str], after: SegmentSums, chosen: Candidate | None
) -> dict | None:
    """The JSON ``base_mismatch`` block, with ``best_removed_nrmse``: what the best single
    effect removes from the structured gap (``decide``: named only from 0.02 on)."""
    tol, rank = diag.tolerances, diag.ranking
    if tol.smooth_nominal is None:
        return None
    bm = basemis.report(
        tol.nominal,
        tol.smooth_nominal,
        tol.floor,
        names,
        (after, rank.smooth[chosen.name]) if chosen is not None else None,
    )
    best = rank.singles[0] if rank.singles else None
    if best is not None and best.name in rank.smooth:
        floor_s = basemis.smoothed_floor(tol.floor)
        removed = basemis.removed_nrmse(tol.smooth_nominal, rank.smooth[best.name], floor_s)
        bm["best_removed_nrmse"] = {"effect": best.effects[0].name, "nrmse": round(removed, 5)}
    return bm
