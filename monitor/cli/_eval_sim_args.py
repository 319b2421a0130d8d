"""The option parsers of ``monitor eval-sim`` (lists of numbers, seeds and names), and its
outputs."""

from __future__ import annotations

import argparse
import json
from typing import Any


def floats(text: str) -> tuple[float, ...]:
    try:
        return tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected numbers separated by commas: {text!r}"
        ) from None


def seeds(text: str) -> tuple[int, ...]:
    """'1-8' or '1,2,5' or a mix."""
    out: list[int] = []
    try:
        for part in (p.strip() for p in text.split(",") if p.strip()):
            lo, _, hi = part.partition("-")
            out += range(int(lo), int(hi) + 1) if hi else [int(lo)]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seeds like 1-8 or 1,2,3: {text!r}") from None
    if not out:
        raise argparse.ArgumentTypeError("no seeds given")
    return tuple(dict.fromkeys(out))


def names(known: tuple[str, ...]) -> Any:
    def parse(text: str) -> tuple[str, ...]:
        names = tuple(n.strip() for n in text.split(",") if n.strip())
        bad = [n for n in names if n not in known]
        if bad or not names:
            raise argparse.ArgumentTypeError(f"choose from {', '.join(known)}: {text!r}")
        return names

    return parse


def fault_names(text: str) -> tuple[str, ...]:
    """The boom loop's fault names, or the whole machine's ``LOOP.FAULT`` (checked against
    the machine's faults once ``--machine`` is known)."""
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    if not names:
        raise argparse.ArgumentTypeError(f"no fault named: {text!r}")
    return names


def boom_defaults(args: argparse.Namespace) -> None:
    """The boom loop's evaluation: no whole-machine fault names; the training defaults."""
    from monitor.errors import ConfigError
    from monitor.evaluation.plan import ISOLATION_RUNS
    from monitor.signals import FAULT_NAMES

    bad = [f for f in args.faults or () if f not in FAULT_NAMES]
    if bad:
        hint = "; LOOP.FAULT names need --machine excavator4" if "." in bad[0] else ""
        raise ConfigError(
            f"--faults {','.join(bad)}: the boom loop's faults are {', '.join(FAULT_NAMES)}{hint}"
        )
    if args.train_duration is None:
        args.train_duration = 300.0
    if args.isolation_runs is None:
        args.isolation_runs = ISOLATION_RUNS


def write_result(args: argparse.Namespace, result: dict[str, Any], text: str) -> None:
    """The JSON to ``--json``; the report to ``--markdown``, else stdout."""
    from monitor.errors import ConfigError

    try:
        args.json.write_text(json.dumps(result, indent=1) + "\n", encoding="utf-8")
        if args.markdown:
            args.markdown.write_text(text + "\n", encoding="utf-8")
        else:
            print(text)
    except OSError as exc:
        raise ConfigError(f"cannot write output: {exc.strerror or exc} ({exc.filename})") from None


def plan_flags(plan: Any, all_faults: tuple[str, ...]) -> list[str]:
    """A rerun command's options for the run plan (``EvalConfig``,
    ``machine_plan.MachinePlan``): runs, severities, onsets, the faults when not
    ``all_faults``, normal hours and the run's timing."""
    return [
        f"--runs {plan.runs}",
        f"--severities {','.join(f'{s:g}' for s in plan.severities)}",
        f"--onsets {','.join(plan.onsets)}",
        *([f"--faults {','.join(plan.faults)}"] if plan.faults != all_faults else []),
        f"--normal-hours {plan.normal_hours:g}",
        f"--duration {plan.duration_s:g} --onset {plan.onset_s:g} --ramp {plan.ramp_s:g}",
    ]
