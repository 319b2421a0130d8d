"""The diagnosis's one-page text summary, rendered from the contract JSON (``document.py``):
the first line says where the gap lies, then the verdict and what it rests on."""

from __future__ import annotations

from monitor.gap.report.bounds import bound_lines
from monitor.signals import UNITS


def summary_text(report: dict) -> str:
    """One page a service engineer reads first; the first line says where the gap lies."""
    lines = [_where_line(report["where"])]
    if report.get("base_mismatch"):
        lines.append(_base_line(report["base_mismatch"]))
    lines.append("")
    v = report["verdict"]
    if v == "none":
        lines += _verdict_none(report)
    elif v == "unexplained":
        lines += _verdict_unexplained(report)
    else:
        lines += _verdict_named(report)
    lines += _timing_line(report.get("timing"))
    if report.get("metering_check"):
        lines.append(f"Valve metering: {report['metering_check']['decided_by']}")
    lines += _mechanism_lines(report.get("mechanism"))
    lines += _friction_line(report.get("friction_check"))
    lines += _load_line(report.get("load_check"))
    lines += _air_line(report.get("air_check"))
    if report.get("slip_check"):
        lines.append(f"Pump slip: {report['slip_check']['evidence']}")
    lines.append(f"Confidence: {report['confidence']:.2f}")
    lines += _bounded(report["calibrated"])
    lines += bound_lines(report.get("calibration_bounds") or [])
    lines += _tables(report)
    rec = report["recording"]
    lines += [
        "",
        f"Recording {rec['source']}: {rec['duration_s']:g} s, {rec['segments']} segments, "
        f"{rec['calibration_s']:g} s calibration / {rec['heldout_s']:g} s held out, "
        f"RodPos {rec['rodpos']}; diagnosis took {report['timings_s']['total']:.0f} s.",
    ]
    return "\n".join(lines) + "\n"


def _mechanism_lines(m: dict | None) -> list[str]:
    """Mechanism first, cause second (``judge/mechanism.py``), when there is one."""
    if not m or not m.get("name"):
        return []
    lines = [f"Mechanism: {m['name']}; cause: {m['cause']} ({m['decided_by']})"]
    judged = [c for c in m.get("causes") or [] if "status" in c]
    if judged:
        lines.append("Causes: " + "; ".join(_cause_text(c) for c in judged))
    if m.get("timing"):
        lines.append(f"Timing: {m['timing']}")
    if m.get("separating_recording"):
        lines.append(f"To tell the causes apart, record: {m['separating_recording']}")
    return lines


def mechanism_line(report: dict) -> str | None:
    """The terminal's line after the verdict: the mechanism, then its cause (kept against
    the look-alikes the recording rejected, or undecided with the recording that would
    decide), so ``unexplained`` with a worn pump's leak reads as pump leakage from wear."""
    m = report.get("mechanism")
    if not m or not m.get("name"):
        return None
    name = f"{m['name']} ({m['signal']})" if m.get("signal") else m["name"]
    judged = [c for c in m.get("causes") or [] if "status" in c]
    rejected = [c["cause"] for c in judged if c["status"] == "rejected"]
    undecided = [c["cause"] for c in judged if c["status"] == "undecided"]
    cause = str(m["cause"])
    if undecided:
        cause = f"undecided ({' or '.join(undecided)})"
    elif rejected:
        cause += f", not {' or '.join(rejected)}"
    by = (report.get("cause_check") or {}).get("decided_by")
    if by and not undecided:
        cause += f" (decided by the {by})"
    line = f"mechanism: {name}; cause: {cause}"
    first = (report.get("suggestion") or [None])[0]
    if report["verdict"] == "unexplained" and first and "heldout_reduction" in first:
        # The verdict's own reduction is the catalogue's (none); the mechanism's term's is not.
        size = f" ({first['coefficient']:.3g} {first['unit']})" if "coefficient" in first else ""
        line += (
            f"; as a term{size} it removes {100 * first['heldout_reduction']:.0f} % of the "
            "held-out gap"
        )
    if m.get("separating_recording"):
        line += f"; to tell the causes apart, record: {m['separating_recording']}"
    return line


def _timing_line(t: dict | None) -> list[str]:
    """Which readings are late and what the others share (``diagnose/timing.py``), when it
    says more than that every reading is on time."""
    if not t or (not t["late_signals"] and (t["shared_ms"] is None or abs(t["shared_ms"]) < 5)):
        return []
    before = t["verdict_without_check"]
    return [f"Readings' timing: {t['decided_by']} (verdict without it: {before})"]


def _cause_text(c: dict) -> str:
    """One cause of a mechanism as its check judged it (``diagnose/cause.py``)."""
    red = c.get("heldout_reduction")
    removed = "" if red is None else f", removes {100 * red:.0f} % of the held-out gap"
    return f"{c['cause']} ({c['law']}{removed}): {c['status']}"


def _friction_line(fc: dict | None) -> list[str]:
    """The rod's force balance, when it named or withdrew a friction (``judge/friction.py``)."""
    if not fc or fc["friction_named"] == (fc["verdict_without_check"] == "cylinder_friction"):
        return []
    return [f"Friction: {fc['evidence']} (verdict without it: {fc['verdict_without_check']})"]


def _load_line(lc: dict | None) -> list[str]:
    """The rod's load at rest, when it named or withdrew a load variation
    (``judge/loadcheck.py``)."""
    if not lc or lc["load_named"] == (lc["verdict_without_check"] == "load_variation"):
        return []
    return [f"Load: {lc['evidence']} (verdict without it: {lc['verdict_without_check']})"]


def _air_line(ac: dict | None) -> list[str]:
    """The drained chambers at rest, when they named entrained air (``judge/aircheck.py``)."""
    if not ac or not ac["air_named"] or ac["verdict_without_check"] == "entrained_air":
        return []
    return [f"Air: {ac['evidence']} (verdict without it: {ac['verdict_without_check']})"]


def _where_line(w: dict) -> str:
    """Where the gap lies: the worst signal, regime, band and window."""
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
    return first + "."


def _verdict_none(report: dict) -> list[str]:
    lines = [
        "Verdict: none: after calibrating tolerances the simulator is within sensor noise "
        "(held-out mean squared residual under 2x the noise on every signal, or under 4x "
        "with no effect explaining the rest), or what remains is base mismatch and a "
        "structured part below the practical level that no effect explains."
    ]
    if report.get("trade_off"):
        lines.append(_trade_line(report["trade_off"]))
    if report.get("lag_check"):
        lines.append(_lag_line(report["lag_check"]))
    return lines


def _verdict_unexplained(report: dict) -> list[str]:
    best = report["ranking"][0]
    if report.get("sensor_check"):
        lines = ["Verdict: unexplained. " + _sensor_line(report["sensor_check"])]
    elif report.get("trade_off"):
        lines = ["Verdict: unexplained. " + _trade_line(report["trade_off"])]
    elif (report.get("cause_check") or {}).get("mechanism"):
        chk = report["cause_check"]
        cause = "wear, not oil viscosity" if chk["cause"] == "wear" else "undecided"
        lines = [
            f"Verdict: unexplained: {chk['mechanism']} ({chk['signal']}), its cause {cause}: "
            "the catalogue names a leak only as oil viscosity, and this recording did not "
            "show that"
        ]
    else:
        lines = [
            "Verdict: unexplained: no catalogue effect removes a clear share of the "
            f"held-out gap (best: {best['effect']}, {100 * best['heldout_reduction']:.0f} %)."
        ]
    if report.get("lag_check"):
        lines.append(_lag_line(report["lag_check"]))
    lines += _what_next(report.get("suggestion") or [], report.get("suggestion_tried") or [])
    return lines


def _verdict_named(report: dict) -> list[str]:
    v, sh = report["verdict"], report["shrink"]
    lines = [f"Verdict: {v} ({_fmt_params(report['params'])})"]
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
    return lines


def _bounded(calibrated: dict) -> list[str]:
    """A warning when a tolerance ended at its bound."""
    bounded = [
        f"{n} {c['change_pct']:+.1f} % (band +-{c['band_pct']:g} %)"
        for n, c in calibrated.items()
        if c.get("at_bound")
    ]
    if not bounded:
        return []
    return [
        f"Tolerance at its bound: {', '.join(bounded)}. The machine is outside the "
        "tolerance the simulator's configuration assumes, or the band took up part of an "
        "effect: check simulator.yaml (nominal values) before trusting the verdict."
    ]


def _tables(report: dict) -> list[str]:
    """Held-out NRMSE per signal, the calibrated tolerances, the candidates, and where."""
    sh, w = report["shrink"], report["where"]
    lines = ["", "Held-out NRMSE per signal (before -> after; sensor noise alone):"]
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
    return lines


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


def _base_line(bm: dict) -> str:
    """Which part of the gap is base mismatch, and the largest structured residual."""
    worst = max(bm["signals"], key=lambda n: bm["signals"][n]["structured_nrmse"])
    level = bm["signals"][worst]["structured_nrmse"]
    return (
        f"Base mismatch: {100 * bm['share']:.0f} % of the gap is above {bm['above_hz']:g} Hz "
        "(the simulator's base dynamics; no catalogue effect produces it); structured part "
        f"largest in {worst} (NRMSE {level:.3f}, practical level {bm['practical_nrmse']:g})."
    )
