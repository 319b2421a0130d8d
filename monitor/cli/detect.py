"""``monitor detect``: run the detector over a recording (candump log or contract CSV)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

import numpy as np

from monitor.cli._detect_pump import add_pump_option, run_pump
from monitor.cli._extras import require
from monitor.cli._paths import output_file
from monitor.detection.alarm import State
from monitor.detection.opstate import OpState
from monitor.errors import MonitorError

if TYPE_CHECKING:
    from monitor.detection.offline import Detection


def add_subparser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "detect",
        help="diagnose a recording: J(k+1), alarms, isolated fault",
        description="Run the DGRNN detector over a candump log or contract CSV. State "
        "changes (and J once per --j-every seconds) go out as JSON lines on stdout or to "
        "--events. The verdict is fault, sensor_fault, healthy, or not_judged: less than one "
        "J window of samples was judged (no commands, shorter than the window, engine off, "
        "warm-up or outside the model's trained range throughout), so the data cannot say "
        "healthy. Exit 0 when the recording was judged, whatever was found; 2 for a bad file "
        "or argument; 3 when it holds no usable hydraulic data or was not judged (the "
        "summary is still written).",
    )
    p.add_argument("recording", type=Path, metavar="REC")
    p.add_argument(
        "--model",
        type=Path,
        default=None,
        help="model file (default: the one config/monitor.yaml names)",
    )
    p.add_argument("--config", type=Path, default=None, help="monitor YAML (default: shipped)")
    p.add_argument(
        "--loop",
        default=None,
        metavar="NAME",
        help="diagnose this loop of a candump log with several loops' frames (the config's "
        "`loops:`; default model: the loop's)",
    )
    p.add_argument(
        "--horizon",
        type=int,
        default=None,
        metavar="P",
        help="prediction horizon p (default: from the config)",
    )
    p.add_argument("--summary", type=output_file, default=None, metavar="F.json")
    p.add_argument(
        "--events",
        type=output_file,
        default=None,
        metavar="F.jsonl",
        help="write the JSON lines here instead of stdout",
    )
    p.add_argument(
        "--j-every",
        type=float,
        default=1.0,
        metavar="S",
        help="also emit J every S seconds (0: state changes only; default 1)",
    )
    p.add_argument("--plot", type=output_file, default=None, metavar="F.png")
    add_pump_option(p)
    p.set_defaults(func=run)


def _lines(det: Detection, j_every_s: float, tag: dict[str, str]) -> list[dict[str, Any]]:
    out = [dict(e, event="state") | tag for e in det.events]
    if j_every_s > 0:
        t = det.t - det.t[0]
        step = max(1, int(round(j_every_s / 0.01)))
        eps0 = det.summary["threshold"]
        # The fault named at each J line is the one of the last state change before it.
        change_t = np.array([e["t"] for e in det.events])
        for i in range(0, len(t), step):
            j = det.j[i]
            k = int(np.searchsorted(change_t, round(float(t[i]), 6), side="right")) - 1
            out.append(
                {
                    "event": "j",
                    "t": round(float(t[i]), 6),
                    "time": None,
                    "state": State(int(det.state[i])).label,
                    "op_state": None if det.gates is None else OpState(det.gates.op_state[i]).label,
                    "J": float(j) if np.isfinite(j) else None,
                    "threshold": eps0,
                    "fault": det.events[k]["fault"] if k >= 0 else None,
                }
                | tag
            )
        out.sort(key=lambda e: (e["t"], e["event"] != "state"))
    return out


def _write_lines(lines: list[dict[str, Any]], fh: TextIO) -> None:
    for line in lines:
        fh.write(json.dumps(line) + "\n")


def run(args: argparse.Namespace) -> int:
    return run_pump(args) if args.pump else _run_loop(args)


def _run_loop(args: argparse.Namespace) -> int:
    if args.plot:
        require("matplotlib")  # the [analysis] extra: said before the work, not after
    from monitor.config.layout import check_loop_model
    from monitor.config.settings import load_config
    from monitor.model.modelfile import load_model
    from monitor.offline.loopjob import check_whole_recording, judge_recording
    from monitor.offline.recordings import read_loop

    cfg = load_config(args.config)
    loop = next((lc for lc in cfg.monitored_loops if lc.name == args.loop), None)
    if args.loop is not None and loop is None:
        read_loop(args.recording, cfg, args.loop)  # raises, naming the file or the loops
    loop = loop or cfg.monitored_loops[0]
    model_path = args.model or (loop.model if args.loop else cfg.model)
    model = load_model(model_path)
    check_loop_model(model, loop, cfg, model_path)  # before the recording is read
    check_whole_recording(args.loop, model, cfg, model_path)
    tag = {} if args.loop is None else {"loop": args.loop}
    # A model not commissioned on the config's machine_id withholds its hydraulic alarms
    # (the daemon applies the same rule).
    judged = judge_recording(model, args.recording, cfg, args.loop, cfg.machine_id, args.horizon)
    rec, det, reference = judged.rec, judged.det, judged.reference
    det.summary.update(tag)
    lines = _lines(det, args.j_every, tag)
    try:
        if args.events:
            with args.events.open("w", encoding="utf-8") as fh:
                _write_lines(lines, fh)
        else:
            _write_lines(lines, sys.stdout)
        if args.summary:
            args.summary.write_text(json.dumps(det.summary, indent=2) + "\n", encoding="utf-8")
        if args.plot:
            from monitor.detection.plot import plot_detection

            plot_detection(rec, det, model.spec.outputs, args.plot)
    except OSError as exc:
        raise MonitorError(f"cannot write output: {exc.strerror or exc} ({exc.filename})") from None
    s = det.summary
    max_j = "n/a" if s["max_J"] is None else f"{s['max_J']:.4g}"
    # The alarm compares the level (each statistic over its threshold, the largest) with 1:
    # its largest value says how close.
    level = "" if s["max_level"] is None else f", max level {s['max_level']:.3g} (1 = alarm)"
    # Said even when nothing was withheld: the verdict rests on another machine's model.
    ref = (
        ""
        if reference is None or s["withheld"]
        else f"; {reference}: a fault would be withheld, not raised (commission this machine "
        "with monitor train to judge it)"
    )
    print(
        f"{args.recording}: {_result_line(s)} (max J {max_j}, eps0 {s['threshold']:.4g}"
        f"{level}, judged {s['judged_s']:.1f} s){ref}",
        file=sys.stderr,
    )
    return 3 if s["verdict"] == "not_judged" else 0


def _result_line(s: dict[str, Any]) -> str:
    if s["verdict"] == "not_judged":
        return f"not judged: {s['not_judged_why']}"
    line = (
        f"FAULT from {s['first_alarm_t']:.2f} s, isolated: {s['fault']}"
        if s["alarm"]
        else "no hydraulic fault"
        if s["verdict"] == "healthy"
        else "sensor fault"
    )
    if s["sensor_fault"] and s["alarm"]:
        line += "; sensor fault seen"
    for c in s["sensor_checks"]:
        line += f"; {c['sensor']} {c['check']} from {c['first_t']:.2f} s"
    for message, reasons in s["rejected"].items():
        line += f"; {message} frames rejected: " + ", ".join(f"{n} {r}" for r, n in reasons.items())
    if s["out_of_range_samples"]:
        line += f"; {s['out_of_range_s']:.1f} s outside the trained range"
    if s.get("judged_beyond_oil_s"):
        line += (
            f", of it {s['judged_beyond_oil_s']:.1f} s on warmer oil judged by F alone (piston "
            "wear only)"
        )
    return line
