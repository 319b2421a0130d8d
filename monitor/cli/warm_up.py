"""``monitor warm-up``: compile every numba kernel into the on-disk cache, once, ahead of time."""

from __future__ import annotations

import argparse
import os
import sys
import time


def add_subparser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "warm-up",
        help="compile the numba kernels into the cache now (after an install, before a start)",
        description="Run every compiled path of the monitor once on shipped data (bulk log "
        "reading, the offline detector, the per-tick detector, the simulator), so that numba "
        "writes its compiled kernels to the on-disk cache and the daemon's first start does "
        "not compile. The cache goes to NUMBA_CACHE_DIR when set (the systemd unit sets "
        "/var/cache/hydraulic-monitor), else next to the installed package. A cache built "
        "with NUMBA_CPU_NAME=generic serves every machine of the same architecture (x86-64 "
        "or aarch64), e.g. built once on an image builder for a fleet of controllers; "
        "without it the kernels are tuned to, and only valid on, this CPU. Then the live "
        "tick's kernels and those of `monitor detect` are compiled ahead of time into a module "
        "beside the cache, so the daemon and `monitor detect` load neither numba nor LLVM "
        "(about 110 MB less memory).",
    )
    p.add_argument(
        "--no-aot",
        dest="aot",
        action="store_false",
        help="do not compile the kernels ahead of time (numba pycc, needs a C++ "
        "compiler, g++); the daemon then loads numba and uses the JIT kernels",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from monitor.jit import cache_stats

    start = time.perf_counter()
    through_jit(simulator=True)
    s = cache_stats()
    where = os.environ.get("NUMBA_CACHE_DIR") or "next to the installed package (__pycache__)"
    cpu = os.environ.get("NUMBA_CPU_NAME") or "this CPU"
    print(
        f"warm-up: {s['kernels']} kernels, {s['hits']} signatures loaded from the cache, "
        f"{s['misses']} compiled, {time.perf_counter() - start:.1f} s; cache: {where}; "
        f"code for: {cpu}",
        file=sys.stderr,
    )
    if args.aot:
        _build_aot()
    return 0


def through_jit(simulator: bool) -> None:
    """Every compiled path once through the JIT (the ahead-of-time module off), so that numba
    knows the kernels' argument types; the simulator's too when ``simulator``."""
    from monitor.config.settings import load_config
    from monitor.detection.offline import detect
    from monitor.detection.ticker import Ticker
    from monitor.model.modelfile import load_model
    from monitor.resources import resource_path
    from monitor.sampling.read import read_recording

    before = os.environ.get("MONITOR_AOT")
    os.environ["MONITOR_AOT"] = "0"  # through the JIT: numba learns the kernels' types
    cfg = load_config()
    model = load_model(cfg.model)
    steps = [
        (
            "log reading and offline detection",
            lambda: detect(
                model,
                read_recording(resource_path("replay", "spool_wear.log")),
                cfg.alarm,
                cfg.horizon,
                gating=cfg.gating,
            ),
        ),
        # The one-thread form `monitor detect` runs ahead of time (a cache hit of the
        # parallel driver does not tell numba the types of the kernel it calls).
        ("offline prediction on one thread", lambda: _serial_prediction(model)),
        (
            "per-tick detector",
            lambda: _ticks(Ticker(model, cfg.alarm, cfg.horizon, gating=cfg.gating)),
        ),
        ("live sample clock", _sample_clock),
        *([("simulator", _simulator)] if simulator else []),
        # A statistic may be opt-in for `monitor train` (H: ``--hold on``): each member's
        # kernels typed here whatever the configured model carries, so any model with it
        # finds them ahead of time.
        ("statistics", _statistics),
    ]
    try:
        for name, step in steps:
            t0 = time.perf_counter()
            if step() is False:
                print(
                    f"warm-up: {name}: skipped (the [analysis] extra is not installed)",
                    file=sys.stderr,
                )
                continue
            print(f"warm-up: {name}: {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    finally:
        if before is None:
            del os.environ["MONITOR_AOT"]
        else:
            os.environ["MONITOR_AOT"] = before


def _build_aot() -> None:
    """The kernels declared ``aot`` (the live tick's, ``monitor detect``'s) ahead of time
    (monitor.jit.aot): the daemon and an offline detection then load no numba."""
    from monitor.jit import KERNELS, Kernel, aot

    tick = [k for k in KERNELS if isinstance(k, Kernel) and k.aot]
    t0 = time.perf_counter()
    try:
        path = aot.build(tick)
    except Exception as exc:  # no C++ compiler, no setuptools: the JIT kernels serve
        print(
            f"warm-up: kernels not compiled ahead of time ({type(exc).__name__}: "
            f"{exc}); the JIT kernels serve",
            file=sys.stderr,
        )
        return
    found = [aot.compiled_function(k.py_func) is not None for k in tick]
    print(
        f"warm-up: {sum(found)} of {len(tick)} kernels (live tick, offline detection) "
        f"compiled ahead of time in {time.perf_counter() - t0:.1f} s: {path} (the daemon "
        f"and monitor detect load no numba)",
        file=sys.stderr,
    )


def _simulator() -> bool:
    """The simulator's kernels, where it is installed (a controller's install has no scipy,
    and no use for the simulator)."""
    from importlib.util import find_spec

    if find_spec("scipy") is None:
        return False
    from monitor.sim.cycles import make_cycle
    from monitor.sim.machine import load_machine
    from monitor.sim.simulate import simulate

    simulate(make_cycle("boom", 2.0, 1), load_machine(), seed=1)
    return True


def _serial_prediction(model: object) -> None:
    import numpy as np

    from monitor.model.dgrnn import predict_series

    dgrnn = model.dgrnn  # type: ignore[attr-defined]
    predict_series(dgrnn, np.zeros((200, len(dgrnn.spec.variables))), serial=True)


def _ticks(ticker: object) -> None:
    """One tick of a zero row: the tick's kernels (gating, plausibility, predictor)."""
    import numpy as np

    from monitor.sampling.sampler import ROW_COLUMNS

    ticker.tick(np.zeros(1 + len(ROW_COLUMNS)))  # type: ignore[attr-defined]


def _sample_clock() -> None:
    """Two frames through the daemon's sampler: the clock's step kernel, called per frame."""
    from monitor.sampling.sampler import Sampler

    sampler = Sampler({"PP": 0.01})
    for k in range(2):
        sampler.feed(k * 0.01, "HYD_Pressures", {"PP": 1.0})


def _statistics() -> None:
    """Every statistic's kernels once on a tiny example (``Statistic.warm``)."""
    from monitor.model.statistic import registry

    for stat in registry():
        stat.warm()
