"""``monitor detect --pump``: the pump rule (``monitor.detection.pump``) over a
whole-machine recording, with the config's pump model."""

from __future__ import annotations

import argparse
import json
import sys

from monitor.errors import ConfigError, MonitorError


def add_pump_option(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--pump",
        action="store_true",
        help="judge the shared load-sensing pump instead (the config's `pump: {model: ...}`, "
        "from `monitor train --pump`): its margin law's mean residual over windows of steady "
        "open flow; events and summary name loop `pump`, fault `pump_wear`",
    )


def run_pump(args: argparse.Namespace) -> int:
    from monitor.config.pump import load_pump, pump_columns
    from monitor.config.settings import load_config
    from monitor.detection.pump import judge_rows
    from monitor.offline.recordings import machine_rows

    if args.loop is not None or args.model is not None:
        raise ConfigError("--pump reads the config's pump model: leave --loop and --model out")
    cfg = load_config(args.config)
    model = load_pump(cfg)
    if model is None:
        raise ConfigError(
            f"{cfg.source}: no `pump: {{model: FILE}}` (train one with monitor train --pump)"
        )
    columns, rows, start_s = machine_rows(args.recording, cfg)
    det = judge_rows(model, pump_columns(cfg, columns), rows, start_s)
    try:
        fh = args.events.open("w", encoding="utf-8") if args.events else sys.stdout
        for ev in det.events:
            fh.write(json.dumps(dict(ev, event="state")) + "\n")
        if args.events:
            fh.close()
        if args.summary:
            args.summary.write_text(json.dumps(det.summary, indent=2) + "\n", encoding="utf-8")
    except OSError as exc:
        raise MonitorError(f"cannot write output: {exc.strerror or exc} ({exc.filename})") from None
    s = det.summary
    if s["verdict"] == "not_judged":
        line = f"pump not judged: {s['not_judged_why']}"
    else:
        found = f"FAULT from {s['first_alarm_t']:.2f} s: pump_wear" if s["alarm"] else "healthy"
        line = (
            f"pump {found} (largest margin residual {s['max_margin_residual_bar']:.4f} bar, "
            f"threshold {s['threshold_bar']:.4f} bar, judged on {s['counted_s']:.1f} s of "
            "steady open flow)"
        )
    print(f"{args.recording}: {line}", file=sys.stderr)
    return 3 if s["verdict"] == "not_judged" else 0
