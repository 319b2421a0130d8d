"""The diagnosis as the contract JSON and a one-page text summary.

JSON keys (issue 6, other tools read them): ``verdict``, ``also``, ``params``,
``calibrated``, ``confidence``, ``where`` {signals, regimes, bands, windows}, ``ranking``,
``shrink`` {before, after, heldout_reduction}; extra keys add detail without changing those.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from monitor.gap.data.prepare import Prepared
from monitor.gap.diagnose.pipeline import Diagnosis
from monitor.gap.fit import calibrate as cal_mod
from monitor.gap.fit import sensorcal
from monitor.gap.fit.candidates import Candidate, default_member
from monitor.gap.fit.predict import predict
from monitor.gap.fit.score import SegmentSums, compared, gap, normalised, reduction
from monitor.gap.judge import basemis
from monitor.gap.judge import where as W
from monitor.gap.judge.shrink import shrink_report
from monitor.signals import MEASURED_NAMES, UNITS
from monitor.sim.effects import CATALOGUE, Effect
from monitor.sim.machine import MachineParams


@dataclass
class Traces:
    """Whole-recording simulations for the report: calibrated nominal and corrected."""

    nominal: dict[str, np.ndarray]
    corrected: dict[str, np.ndarray] | None


def simulate_all(diag: Diagnosis, machine: MachineParams) -> Traces:
    prep, segs = diag.prep, diag.segments
    nominal = predict(prep, segs, diag.machine, ())
    corrected = None
    if diag.chosen is not None:
        m = cal_mod.apply(machine, diag.chosen.factors)
        # Started from the rod path the hypothesis reads (``reread.py``), if its own.
        own = diag.chosen.prep if diag.chosen.prep is not None else prep
        corrected = predict(own, segs, m, diag.chosen.effects)
    return Traces(nominal, corrected)


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


def _regime_shrink(diag: Diagnosis, traces: Traces, held_mask: np.ndarray) -> list[dict]:
    prep = diag.prep
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


def build_report(diag: Diagnosis, machine: MachineParams, traces: Traces) -> dict:
    """The JSON document (plain types only)."""
    prep = diag.prep
    all_mask = W.scored_mask(len(prep), diag.segments)
    held_mask = W.scored_mask(len(prep), diag.heldout)
    resid = normalised(prep, traces.nominal)
    chosen = diag.chosen
    after = diag.sums[chosen.name] if chosen is not None else diag.nominal
    shrink = shrink_report(
        diag.nominal,
        after,
        diag.boot_idx,
        diag.floor,
        _regime_shrink(diag, traces, held_mask),
        compared(prep),
    )
    params: dict[str, dict] = {}
    also_params = None
    member = also_member = None
    if chosen is not None:
        by_name = {e.name: e for e in chosen.effects}
        mem = dict(zip(by_name, chosen.members or map(default_member, by_name), strict=True))
        params = effect_params(by_name[diag.verdict], _fitted(mem[diag.verdict]))
        member = mem[diag.verdict].name
        if diag.also is not None:
            also_params = effect_params(by_name[diag.also], _fitted(mem[diag.also]))
            also_member = mem[diag.also].name
    duration = float(prep.t[-1] - prep.t[0])
    return {
        "verdict": diag.verdict,
        "also": diag.also,
        "params": params,
        "also_params": also_params,
        # Which formulation of the effect's family fitted (issue 18; "default" for effects
        # with one formulation).
        "member": member,
        "also_member": also_member,
        "calibrated": cal_mod.describe(machine, chosen.factors if chosen else diag.factors),
        "confidence": round(float(diag.confidence), 3),
        "where": {
            "signals": W.by_signal(resid, all_mask),
            "regimes": W.by_regime(prep, resid, all_mask),
            "bands": W.by_band(prep, resid),
            "windows": W.worst_windows(prep, resid, all_mask),
        },
        "ranking": [_candidate_row(c) for c in diag.singles],
        "pairs": [_candidate_row(c) for c in diag.pairs],
        "shrink": shrink,
        "base_mismatch": _base_mismatch(diag, compared(prep), after, chosen),
        "recording": {
            "source": prep.source,
            "duration_s": round(duration, 2),
            "rodpos": _rodpos(prep, chosen),
            "segments": len(diag.segments),
            "calibration_s": round(sum(s.duration_s() for s in diag.calibration), 1),
            "heldout_s": round(sum(s.duration_s() for s in diag.heldout), 1),
        },
        "timings_s": {k: round(v, 2) for k, v in diag.timings_s.items()},
        **(
            {"suggestion": diag.suggestion, "suggestion_tried": diag.suggestion_tried}
            if diag.verdict == "unexplained"
            else {}
        ),
        **({"sensor_check": diag.sensor_check} if diag.sensor_check is not None else {}),
        **({"trade_off": diag.traded} if diag.traded is not None else {}),
        **({"lag_check": diag.lag_check} if diag.lag_check is not None else {}),
        **_absorbed(diag),
    }


def _absorbed(diag: Diagnosis) -> dict:
    """The JSON ``absorbed``: the named effect's tolerances that the calibration had taken
    to their bound in its place (``diagnose.calibration_absorbed``), and the share of the
    held-out gap of its own tolerances without it that the effect removes (what it was
    judged on)."""
    # Keyed by single effects: a pair or no verdict has none.
    chosen = diag.chosen
    a = diag.absorbed.get(chosen.name) if chosen is not None else None
    if chosen is None or a is None:
        return {}
    without = gap(a.sums[0].mse(), diag.floor)
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


def _absorbed_line(a: dict) -> str:
    """Which tolerances stood in for the named effect, and what it was judged on."""
    moved = "; ".join(
        f"{t} {v['calibration_pct']:+.0f} % (its bound), {v['with_effect_pct']:+.0f} % when "
        "fitted with the effect"
        for t, v in a["tolerances"].items()
    )
    return (
        f"Calibration alone: {moved}. Against those tolerances without it, {a['effect']} "
        f"removes {100 * a['heldout_reduction']:.0f} % of the held-out gap."
    )


def _trade_line(t: dict) -> str:
    """Why the best effect was not named (``consistency.py``)."""
    return (
        f"Not {t['effect']} ({t['member']}): it removes {100 * t['heldout_reduction']:.0f} % of "
        f"the held-out gap but makes {t['signal']} clearly worse (+{100 * t['growth_share']:.0f} "
        "% of the gap); the effect's physics would move every signal towards the recording, "
        "so what it fitted is base mismatch or something outside the catalogue."
    )


def _lag_line(check: dict) -> str:
    """How the readings followed the engine's speed ripple (``lagcheck``)."""
    if check["readings"] == "undecided":
        return (
            "Sensor lag checked against the engine's speed ripple: undecided (too little "
            "ripple, or a fitted lag too short, to tell a late reading from a prompt one)."
        )
    qp = next((r for r in check["signals"] if r["signal"] == "QP"), None)
    where = (
        f" (QP at {qp['position']:.2f} of the way from late to prompt)"
        if qp and qp["position"] is not None
        else ""
    )
    if check["readings"] == "prompt":
        if check["verdict_without_check"] != "sensor_lag":
            return (
                f"Sensor lag ruled out: QP and PP follow the engine's speed ripple promptly{where}."
            )
        return (
            "Not a sensor lag: QP and PP follow the engine's speed ripple promptly"
            f"{where}, z {check['prompt_z']:.1f}; a late reading would show it late.  The "
            "delay is in the plant (what the spool drives)."
        )
    late = (
        f"QP and PP follow the engine's speed ripple as late as the fitted sensor lag{where}, "
        f"z {check['late_z']:.1f}; a slow spool would leave it prompt"
    )
    if check["sensor_named"]:
        return f"Sensor lag: {late}."
    return f"Readings late: {late}, but the sensor lag alone does not explain the gap."


def _sensor_line(check: dict) -> str:
    """How the sensor calibration fared against the best plant term (``sensorphysics``)."""
    red = 100 * check["sensor_heldout_reduction"]
    sens = f"a {check['signal']} sensor calibration removes {red:.0f} %"
    term = f"{check['term']} removes {100 * check['term_heldout_reduction']:.0f} %"
    if check["sensor_named"]:
        return f"Sensor, not physics: {sens}; the best plant term, {term}."
    return (
        f"Not a sensor error: {sens} of the held-out gap, but the plant term {term} across "
        "all signals (a reading error cannot move the other signals' physics)."
    )


def _fmt_params(params: dict[str, dict]) -> str:
    return ", ".join(
        f"{k} = {v['value']:.4g} {v['unit']}"
        for k, v in params.items()
        if v.get("fitted")  # sensor_calibration's plain copy has no "fitted"
    )


def _what_next(suggestion: list[dict], tried: list[dict]) -> list[str]:
    """The lines "What to model next": the suggested terms, each with its held-out reduction
    (or the best term tried, when none removes a material share)."""
    if not suggestion:
        if not tried:
            return []
        t = tried[0]
        return [
            "What to model next: no term of the correction library removes a material share "
            f"of the held-out gap (best: {t['term']} {t['signal']}, "
            f"{100 * t['heldout_reduction']:.0f} %)."
        ]
    out = ["What to model next:"]
    for i, s in enumerate(suggestion):
        plus = "" if i == 0 else " (together with the above)"
        out.append(
            f"  {s['term']} ({s['signal']}): {s['description']}; removes "
            f"{100 * s['heldout_reduction']:.0f} % of the held-out gap{plus}"
        )
    return out


def _base_mismatch(
    diag: Diagnosis, names: Sequence[str], after: SegmentSums, chosen: Candidate | None
) -> dict | None:
    """The JSON ``base_mismatch`` block, with ``best_removed_nrmse``: what the best single
    effect removes from the structured gap (``decide``: named only from 0.02 on)."""
    if diag.smooth_nominal is None:
        return None
    bm = basemis.report(
        diag.nominal,
        diag.smooth_nominal,
        diag.floor,
        names,
        (after, diag.smooth[chosen.name]) if chosen is not None else None,
    )
    best = diag.singles[0] if diag.singles else None
    if best is not None and best.name in diag.smooth:
        floor_s = basemis.smoothed_floor(diag.floor)
        removed = basemis.removed_nrmse(diag.smooth_nominal, diag.smooth[best.name], floor_s)
        bm["best_removed_nrmse"] = {"effect": best.effects[0].name, "nrmse": round(removed, 5)}
    return bm


def _base_line(bm: dict) -> str:
    """Which part of the gap is base mismatch, and the largest structured residual."""
    worst = max(bm["signals"], key=lambda n: bm["signals"][n]["structured_nrmse"])
    level = bm["signals"][worst]["structured_nrmse"]
    return (
        f"Base mismatch: {100 * bm['share']:.0f} % of the gap is above {bm['above_hz']:g} Hz "
        "(the simulator's base dynamics; no catalogue effect produces it); structured part "
        f"largest in {worst} (NRMSE {level:.3f}, practical level {bm['practical_nrmse']:g})."
    )


def summary_text(report: dict) -> str:
    """One page a service engineer reads first; the first line says where the gap lies."""
    w = report["where"]
    sig = w["signals"][0]
    reg = w["regimes"][0] if w["regimes"] else None
    band = w["bands"][0]
    win = w["windows"][0] if w["windows"] else None
    first = f"Gap mostly in {sig['name']} (NRMSE {sig['nrmse']:.3f})"
    if reg:
        first += f", concentrated in '{reg['regime']}' ({reg['concentration']:.1f}x its time share)"
    first += f", {band['band_hz'][0]:g}-{band['band_hz'][1]:g} Hz ({100 * band['share']:.0f} %)"
    if win:
        first += f", worst at {win['t_start']:g}-{win['t_end']:g} s"
    lines = [first + "."]
    if report.get("base_mismatch"):
        lines.append(_base_line(report["base_mismatch"]))
    lines.append("")
    v = report["verdict"]
    sh = report["shrink"]
    if v == "none":
        lines.append(
            "Verdict: none: after calibrating tolerances the simulator is within sensor noise "
            "(held-out mean squared residual under 2x the noise on every signal, or under 4x "
            "with no effect explaining the rest), or what remains is base mismatch and a "
            "structured part below the practical level that no effect explains."
        )
        if report.get("trade_off"):
            lines.append(_trade_line(report["trade_off"]))
        if report.get("lag_check"):
            lines.append(_lag_line(report["lag_check"]))
    elif v == "unexplained":
        best = report["ranking"][0]
        if report.get("sensor_check"):
            lines.append("Verdict: unexplained. " + _sensor_line(report["sensor_check"]))
        elif report.get("trade_off"):
            lines.append("Verdict: unexplained. " + _trade_line(report["trade_off"]))
        else:
            lines.append(
                "Verdict: unexplained: no catalogue effect removes a clear share of the "
                f"held-out gap (best: {best['effect']}, {100 * best['heldout_reduction']:.0f} %)."
            )
        if report.get("lag_check"):
            lines.append(_lag_line(report["lag_check"]))
        lines += _what_next(report.get("suggestion") or [], report.get("suggestion_tried") or [])
    else:
        lines.append(f"Verdict: {v} ({_fmt_params(report['params'])})")
        if report.get("sensor_check"):
            lines.append(_sensor_line(report["sensor_check"]))
        if report.get("lag_check"):
            lines.append(_lag_line(report["lag_check"]))
        if report.get("absorbed"):
            lines.append(_absorbed_line(report["absorbed"]))
        if report.get("member") not in (None, "default"):
            lines.append(f"Formulation: {report['member']} (of the {v} family)")
        if report["also"]:
            lines.append(f"Also:    {report['also']} ({_fmt_params(report['also_params'])})")
        lo, hi = sh["heldout_reduction_ci90"]
        lines.append(
            f"Held-out gap removed: {100 * sh['heldout_reduction']:.0f} % "
            f"(90 % bootstrap interval {100 * lo:.0f}..{100 * hi:.0f} %)"
        )
    lines.append(f"Confidence: {report['confidence']:.2f}")
    bounded = [
        f"{n} {c['change_pct']:+.1f} % (band +-{c['band_pct']:g} %)"
        for n, c in report["calibrated"].items()
        if c.get("at_bound")
    ]
    if bounded:
        lines.append(
            f"Tolerance at its bound: {', '.join(bounded)}. The machine is outside the "
            "tolerance the simulator's configuration assumes, or the band took up part of an "
            "effect: check simulator.yaml (nominal values) before trusting the verdict."
        )
    lines += ["", "Held-out NRMSE per signal (before -> after; sensor noise alone):"]
    for n in sh["before"]:
        lines.append(
            f"  {n:3s} [{UNITS.get(n, 'mm/s')}]  {sh['before'][n]:.4f} -> {sh['after'][n]:.4f}"
            f"   (noise {sh['noise_floor_nrmse'][n]:.4f})"
        )
    lines += ["", "Tolerances calibrated first:"]
    for name, c in report["calibrated"].items():
        lines.append(
            f"  {name:17s} {c['value']:.5g} {c['unit']} "
            f"({c['change_pct']:+.1f} %, band +-{c['band_pct']:g} %)"
            + ("  AT ITS BOUND" if c.get("at_bound") else "")
        )
    lines += ["", "Candidates (held-out gap removed, best first):"]
    for row in report["ranking"]:
        mem = ", ".join(m for m in row["members"].values() if m != "default")
        lines.append(
            f"  {row['effect']:22s} {100 * row['heldout_reduction']:6.1f} %"
            + (f"  ({mem})" if mem else "")
        )
    for row in report["pairs"]:
        lines.append(f"  pair {row['effect']:17s} {100 * row['heldout_reduction']:6.1f} %")
    lines += ["", "Where (calibrated nominal simulator, all segments):"]
    for r in w["regimes"][:4]:
        lines.append(
            f"  {r['regime']:44s} {100 * r['share']:5.1f} % of residual in "
            f"{100 * r['time_share']:5.1f} % of time"
        )
    for b in w["bands"][:3]:
        lines.append(
            f"  {b['band_hz'][0]:g}-{b['band_hz'][1]:g} Hz: "
            f"{100 * b['share']:.0f} % of residual power, "
            f"coherence with SpoolCmd {b['coherence_spool']:.2f}"
        )
    rec = report["recording"]
    lines += [
        "",
        f"Recording {rec['source']}: {rec['duration_s']:g} s, {rec['segments']} segments, "
        f"{rec['calibration_s']:g} s calibration / {rec['heldout_s']:g} s held out, "
        f"RodPos {rec['rodpos']}; diagnosis took {report['timings_s']['total']:.0f} s.",
    ]
    return "\n".join(lines) + "\n"
