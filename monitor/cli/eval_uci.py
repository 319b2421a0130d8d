"""``monitor eval-uci --train DIR --test DIR --json F``: DGRNN detection on the real rig."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from monitor.cli._paths import output_file
from monitor.errors import ConfigError
from monitor.evaluation.uci_presets import DETECTION_KEYS, UCI_PRESETS, WINDOWS
from monitor.model.threshold import THRESHOLD_RULES, ThresholdRule

_DESCRIPTION = """\
Fit a DGRNN on the healthy cycles of a ZeMA hydraulic-rig folder (UCI "Condition
monitoring of hydraulic systems": one tab-separated file per sensor, one row per 60 s
cycle at 1 Hz, profile.txt, optional cycles.txt), hold every 3rd healthy cycle out for J0,
choose the preset and J window on --train alone, then score every --test cycle: a cycle
alarms when its largest J exceeds eps0 = factor x J0 (2).  Healthy = valve 100 %, no pump leakage,
accumulator 130 bar, any cooler state and stable flag.  When --train and --test are the same
folder, even original cycle numbers train and odd ones are scored.
"""


def add_subparser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "eval-uci",
        help="real-rig evaluation (UCI hydraulic test rig): detection and false-alarm rates",
        description=_DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--train", metavar="DIR", type=Path, required=True, help="rig folder to fit on")
    p.add_argument("--test", metavar="DIR", type=Path, required=True, help="rig folder to score")
    p.add_argument(
        "--json", metavar="FILE", type=output_file, required=True, help="results to write"
    )
    p.add_argument(
        "--preset",
        choices=tuple(UCI_PRESETS),
        action="append",
        default=None,
        help="preset(s) to try (repeatable; default: all, the best on --train is the default)",
    )
    p.add_argument(
        "--window",
        metavar="N",
        type=int,
        action="append",
        default=None,
        help=f"J window N to try (repeatable; default {', '.join(map(str, WINDOWS))})",
    )
    p.add_argument(
        "--threshold-rule",
        choices=THRESHOLD_RULES,
        default="max",
        help="how J0 is taken from held-out healthy cycles (default max)",
    )
    p.add_argument("--factor", type=float, default=2.0, help="eps0 = factor * J0 (default 2)")
    p.add_argument(
        "--max-cycles",
        metavar="K",
        type=int,
        default=None,
        help="keep K cycles of each side, evenly spread (quick runs and tests)",
    )
    p.set_defaults(func=run)


def _fmt(v: Any) -> str:
    return "   -" if v is None else f"{100 * v:5.1f}%"


def run(args: argparse.Namespace) -> int:
    from monitor.evaluation.uci import evaluate

    if args.json.parent and not args.json.parent.is_dir():
        raise ConfigError(f"--json {args.json}: folder {args.json.parent} does not exist")
    rule = ThresholdRule(args.threshold_rule, factor=args.factor)
    result = evaluate(
        args.train,
        args.test,
        presets=tuple(args.preset or UCI_PRESETS),
        windows=tuple(args.window or WINDOWS),
        rule=rule,
        max_cycles=args.max_cycles,
        progress=lambda msg: print(f"eval-uci: {msg}", file=sys.stderr, flush=True),
    )
    try:
        args.json.write_text(json.dumps(result, indent=2) + "\n")
    except OSError as exc:
        raise ConfigError(f"--json {args.json}: cannot write ({exc.strerror})") from None

    presets = result["presets"]
    names = list(presets)
    print(f"{'condition':18s}" + "".join(f"{n:>12s}" for n in names))
    rows: list[tuple[str, str, str | None]] = [
        ("healthy (false al.)", "healthy_false_alarm_rate", None)
    ]
    rows += [(f"{c}={v}", "detection", f"{c}={v}") for c, v in DETECTION_KEYS]
    for label, key, sub in rows:
        cells = []
        for n in names:
            t = presets[n]["test"]
            cells.append(_fmt(t[key] if sub is None else t[key][sub]))
        print(f"{label:18s}" + "".join(f"{c:>12s}" for c in cells))
    ch = result["model"]
    print(
        f"default: {result['default_preset']} (N={ch['window_N']}, sigma={ch['sigma']:.4g}, "
        f"J0={ch['J0']:.4g}, eps0={ch['eps0']:.4g}, "
        + (
            f"B over {ch['bias_phase_s']} s phases, b0={ch['b0']:.3g}"
            if ch["bias_phase_s"]
            else "J alone"
        )
        + f"); {result['split']['test_cycles']} test "
        f"cycles; {result['runtime_s']:.0f} s; -> {args.json}"
    )
    return 0
