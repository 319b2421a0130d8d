"""``monitor train --pump``: the shared pump's margin law and threshold from whole-machine
normal recordings (``monitor.training.pump``), written as a pump model file that the config's
``pump: {model: FILE}`` names."""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

from monitor.errors import ConfigError, MonitorError


def add_pump_option(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--pump",
        action="store_true",
        help="learn the shared load-sensing pump's margin law instead (needs --config with "
        "`loops:` and plausibility.pump_system: load_sensing, and --held-out normal "
        "recordings for its threshold; --out a .json pump model for the config's `pump:`)",
    )


def run_pump(args: argparse.Namespace) -> int:
    from monitor.config.pump import pump_columns
    from monitor.config.settings import load_config
    from monitor.model.pumplaw import save_pump_model
    from monitor.offline.recordings import machine_rows
    from monitor.training.pump import fit_pump

    if args.loop is not None:
        raise ConfigError("--pump judges the pump every loop shares: leave --loop out")
    if not args.held_out:
        raise ConfigError("--pump needs --held-out normal recordings: its threshold is set on them")
    cfg = load_config(args.config)
    pump = cfg.gating.plausibility.pump
    if not cfg.loops or not pump.load_sensing:
        raise ConfigError(
            f"{cfg.source}: --pump needs `loops:` on one load-sensing pump "
            "(plausibility.pump_system: load_sensing)"
        )

    columns: tuple[str, ...] = ()

    def read(paths: list, what: str) -> list:
        nonlocal columns
        out = []
        for path in paths:
            columns, rows, _ = machine_rows(path, cfg)
            print(f"read {path}{what}: {len(rows) / 100:.0f} s", file=sys.stderr)
            out.append(rows)
        return out

    fits, held = read(args.recordings, ""), read(args.held_out, " (held out)")
    cols = pump_columns(cfg, columns)
    model = fit_pump(fits, held, cols, pump.ls_margin_bar, lambda m: print(m, file=sys.stderr))
    trained = {
        "recordings": [Path(p).name for p in args.recordings],
        "held_out": [Path(p).name for p in args.held_out],
        "machine_id": cfg.machine_id,
    }
    try:
        save_pump_model(replace(model, trained=trained), args.out)
    except OSError as exc:
        raise MonitorError(f"cannot write {args.out}: {exc.strerror or exc}") from None
    print(f"wrote {args.out}", file=sys.stderr)
    return 0
