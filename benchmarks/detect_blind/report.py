"""The fleet's verdicts against the key, and the Markdown table of a scored run."""

from __future__ import annotations

WEAR_MUST_ALARM = 0.45  # the bar: wear at this severity or more alarms


def fleet_summary(df, key: dict, exit_code: int) -> dict:
    """Healthy, uncommissioned and wearing machines' rows of logs.parquet, by the key."""
    truth = {
        e["path"].removeprefix("fleet/"): e
        for e in key["files"]
        if e["path"].startswith("fleet/") and e["kind"] != "commissioning"
    }
    commissioned = {
        e["machine"]
        for e in key["files"]
        if e["path"].startswith("fleet/") and e["kind"] == "commissioning"
    }
    rows = []
    for r in df.to_dict("records"):
        e = truth.get(r["log"])
        if e is None:
            continue
        rows.append(
            {
                "log": r["log"],
                "machine": r["machine"],
                "kind": e["kind"],
                "fault": e["fault"],
                "severity": e["severity"],
                "commissioned": e["machine"] in commissioned,
                "verdict": r["verdict"],
                "alarm": bool(r["alarm"]),
                "fault_named": r["fault"],
                "sensor_fault": bool(r["sensor_fault"]),
                "model": r.get("model"),
                "max_j_ratio": r.get("max_j_ratio"),
                # An all-empty parquet column reads back as NaN, not None: no error.
                "error": r["error"] if isinstance(r.get("error"), str) else None,
            }
        )
    healthy = [r for r in rows if r["kind"] == "normal" and r["commissioned"]]
    bare = [r for r in rows if r["kind"] == "normal" and not r["commissioned"]]
    worn = [r for r in rows if r["kind"] == "wear" and r["severity"] >= WEAR_MUST_ALARM]
    slight = [r for r in rows if r["kind"] == "wear" and r["severity"] < WEAR_MUST_ALARM]
    return {
        "exit": exit_code,
        "logs_in_key": len(truth),
        "rows_matched": len(rows),
        "healthy_commissioned": _count(healthy),
        "healthy_uncommissioned": _count(bare),
        "wear_at_least_0.45": _count(worn),
        "wear_below_0.45": _count(slight),
        "rows": rows,
    }


def _count(rows: list[dict]) -> dict:
    verdicts: dict[str, int] = {}
    for r in rows:
        verdicts[str(r["verdict"])] = verdicts.get(str(r["verdict"]), 0) + 1
    alarmed = [r for r in rows if r["alarm"]]
    return {
        "logs": len(rows),
        "alarm": len(alarmed),
        "sensor_fault": sum(r["sensor_fault"] for r in rows),
        "named_right": sum(r["fault_named"] == r["fault"] for r in alarmed),
        "errors": sum(r["error"] is not None for r in rows),
        "verdicts": verdicts,
    }


def _fmt(x, spec: str = ".2f") -> str:
    return "-" if x is None else format(x, spec)


def markdown(result: dict) -> str:
    """A short table: false alarms, sensor faults, detection and isolation per type; fleet."""
    seed = result["seed"]
    lines = [
        f"# detect_blind, seed {seed} ({'blind' if result['blind'] else 'development'})",
        "",
        "| type | normal h judged | false alarms | per h | 95 % upper per h "
        "| sensor-fault logs: normal, all | normal not judged | isolation |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for tname, t in result["types"].items():
        fa = t["false_alarms"]
        lines.append(
            f"| {tname} | {_fmt(fa['hours'])} | {fa['events']} "
            f"({t['normal_logs_alarming']}/{t['normal_logs']} logs) | "
            f"{_fmt(fa['per_h'])} | {_fmt(fa['upper95_per_h'])} | "
            f"{t['sensor_fault_normal_logs']}/{t['normal_logs']}, "
            f"{t['sensor_fault_logs']}/{t['logs']} | "
            f"{t['normal_not_judged']} | {_fmt(t['isolation_all'], '.0%')} |"
        )
    lines += [
        "",
        "| type | fault @ severity | detected | not judged | early alarms "
        "| median delay s | named right | named |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for tname, t in result["types"].items():
        for name, d in t["faults"].items():
            lines.append(
                f"| {tname} | {name} | {d['detected']}/{d['runs']} | "
                f"{d['not_judged']} | {d['early_alarms']} | "
                f"{_fmt(d['median_delay_s'], '.0f')} | "
                f"{d['isolated']}/{d['detected']} | {', '.join(d['named'])} |"
            )
    fleet = result.get("fleet")
    if fleet and "rows" in fleet:
        lines += [
            "",
            f"Fleet (`monitor fleet run --workers 1`, exit {fleet['exit']}, "
            f"{fleet['rows_matched']}/{fleet['logs_in_key']} logs):",
            "",
            "| machines | logs | alarm | sensor fault | verdicts |",
            "|---|---|---|---|---|",
        ]
        for label, k in (
            ("healthy, commissioned", "healthy_commissioned"),
            ("healthy, no commissioning", "healthy_uncommissioned"),
            ("wearing, severity >= 0.45", "wear_at_least_0.45"),
            ("wearing, severity < 0.45", "wear_below_0.45"),
        ):
            c = fleet[k]
            verdicts = ", ".join(f"{v} {n}" for v, n in sorted(c["verdicts"].items()))
            lines.append(
                f"| {label} | {c['logs']} | {c['alarm']} | {c['sensor_fault']} | {verdicts} |"
            )
    elif fleet:
        lines += ["", f"Fleet: {fleet}"]
    return "\n".join(lines) + "\n"
