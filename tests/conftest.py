"""Fixtures shared by the test modules, and the environment of the monitor processes they start."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

# The shared helpers assert too: rewritten, a failed comparison of event lists shows the diff.
pytest.register_assert_rewrite("live_support", "sim_support", "fleet_support")

# Tests start `python -m monitor ...` processes; in a checkout that is not pip-installed these
# must import this tree's package, whatever their working directory.
os.environ["PYTHONPATH"] = os.pathsep.join(
    p for p in (str(REPO), os.environ.get("PYTHONPATH", "")) if p
)


@pytest.fixture(autouse=True)
def _daemon_logging_removed():
    """`monitor run` called in-process (tests of its start and stop) sets the root logger up
    for journald, at INFO: taken off after the test, so a later test's in-process command
    does not print the daemon's INFO lines on its stderr."""
    import logging

    from monitor.live.journal import JournalFormatter

    root = logging.getLogger()
    level = root.level
    yield
    for h in [h for h in root.handlers if isinstance(h.formatter, JournalFormatter)]:
        root.removeHandler(h)
    root.setLevel(level)


@pytest.fixture(scope="session")
def shipped_config():
    """config/monitor.yaml as shipped (DBC, model and gating defaults)."""
    from monitor.config.settings import load_config

    return load_config()


@pytest.fixture(scope="session")
def model(shipped_config):
    """The shipped model, loaded once for the whole session (read-only in every test)."""
    from monitor.model.modelfile import load_model

    return load_model(shipped_config.model)


@pytest.fixture(scope="session")
def warm_numba_cache(tmp_path_factory) -> tuple[list[str], Path]:
    """``monitor warm-up`` twice into a numba cache of its own, empty before: (stderr of each
    run, the cache folder).  Shared by test_startup (the cache's own checks) and test_bench
    (its warm figures), which run on one worker (SHARED_GROUPS): one cold compile of every
    kernel and one build of the ahead-of-time module for both, not two.  The first run is
    ``--no-aot`` (its module would be built again, the same, by the second): the module is
    built from the kernels' types as the cache gives them (build-controller's test builds
    one after a compile)."""
    import subprocess
    import sys

    cache = tmp_path_factory.mktemp("warm") / "cache"
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    runs = [
        subprocess.run(
            [sys.executable, "-m", "monitor", "warm-up", *args],
            capture_output=True,
            text=True,
            env=env,
            check=True,
        ).stderr
        for args in (["--no-aot"], [])
    ]
    return runs, cache


# Under pytest-xdist (CI: ``-n auto --dist loadgroup``) a test file is one unit of work, run on
# one worker, as with ``--dist loadfile``; but the files below, the heaviest, are split: each
# test of theirs is a unit of its own, unless it uses a fixture of module (or class) scope,
# which is then built once on one worker for all the tests that use it.  The heaviest go
# first, so no long file starts last and leaves the other worker idle at the end.  The
# seconds are one file's share of a CI run (2 workers, load 3) as ``--durations`` showed it
# (the 25 slowest; the others from a run at load 15, divided by 5): only an order, a stale
# figure costs balance, never a result.  Only files whose tests share no bus group, port,
# file or CPU hog with each other are split: two of their tests may run at once.
HEAVY_FILES: dict[str, float] = {
    "test_gap_sensor_cal.py": 200,
    "test_gap_suggest.py": 135,
    "test_eval_sim.py": 90,
    "test_gap_cli.py": 75,
    "test_gap_families.py": 70,
    "test_hold.py": 30,
    "test_gap_reread.py": 30,
    "test_gap_lagcheck.py": 27,
    "test_gap_rank.py": 18,
}
#: The heaviest files kept whole (one unit, on one worker), in the same order.
HEAVY_WHOLE: dict[str, float] = {
    "test_live_field.py": 160,
    # test_fleet_pump, _loops and _commission_support: their module fixtures commission
    # simulated machines (223, 72 and 35 CPU-seconds at load 10; about 120 of the first on CI).
    "test_fleet_pump.py": 130,
    "test_bench.py": 120,
    "test_fleet.py": 100,
    "test_attack_flood.py": 100,
    "test_gap_bench.py": 90,
    "test_startup.py": 80,
    "test_attack_restart.py": 75,
    "test_controller_wheel.py": 60,
    "test_install.py": 55,
    "test_fleet_loops.py": 45,
    "test_fleet_browser.py": 41,
    "test_sim_faults_effects.py": 32,
    "test_fleet_scheduler.py": 32,
    "test_grnn_index.py": 22,
    "test_fleet_commission_support.py": 20,
    "test_detector.py": 17,
    "test_crossfit.py": 13,
}


#: Started before all others, so that in a clean clone one worker alone compiles the
#: simulator's kernels into the checkout's cache (about 30 CPU-seconds, for its first gap
#: test), where otherwise every worker compiled them at once: test_bench and test_startup
#: (one unit, SHARED_GROUPS) compile into a cache of their own (a temporary NUMBA_CACHE_DIR,
#: by design), and test_live_field's first test needs no simulator (its daemon mostly waits
#: on a replay at the log's speed, beside the compiles).
STARTS_FIRST = ("test_bench.py", "test_startup.py", "test_live_field.py")
#: Files whose tests share a session fixture: one unit of work together, so that the
#: fixture is built once, on one worker.
SHARED_GROUPS = {"test_bench.py": "warm_numba_cache", "test_startup.py": "warm_numba_cache"}


def _shares_a_fixture(item: pytest.Item) -> bool:
    """Whether the test uses a fixture built once for several tests of its file."""
    info = getattr(item, "_fixtureinfo", None)
    if info is None:
        return False
    return any(
        defs[-1].scope in ("module", "class", "package")
        for name in info.names_closure
        if (defs := info.name2fixturedefs.get(name))
    )


@pytest.hookimpl(optionalhook=True)  # an xdist hook
def pytest_xdist_auto_num_workers(config) -> int | None:
    """``-n auto``: one worker per core, and one more.  About a quarter of the suite's time
    is tests that wait on the wall clock (logs replayed onto a bus at its speed, daemons
    started and stopped: a few percent of a core each); with one worker per core, the core
    of the worker running one idled.  PYTEST_XDIST_AUTO_NUM_WORKERS still wins."""
    if os.environ.get("PYTEST_XDIST_AUTO_NUM_WORKERS"):
        return None
    return (len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else 1) + 1


def pytest_addoption(parser) -> None:
    import cpu_time

    cpu_time.addoption(parser)


def pytest_configure(config) -> None:
    """Under ``--dist loadgroup`` the units go out in the order of the collection (below),
    not sorted by their number of tests (xdist's default); ``--cpu-durations`` (cpu_time.py)."""
    import cpu_time

    cpu_time.configure(config)
    if config.getoption("dist", "no") == "loadgroup":
        config.option.loadscopereorder = False


@pytest.hookimpl(tryfirst=True)  # before xdist's own hook reads the xdist_group marks
def pytest_collection_modifyitems(config, items) -> None:
    if not getattr(config.option, "loadgroup", False):  # set in the workers of a loadgroup run
        return
    weight = {**HEAVY_WHOLE, **HEAVY_FILES}
    for item in items:
        name = item.path.name
        if name not in HEAVY_FILES or _shares_a_fixture(item):
            item.add_marker(pytest.mark.xdist_group(SHARED_GROUPS.get(name, name)))
    # Stable: the order within a file is kept, so tests sharing a fixture stay together.
    items.sort(
        key=lambda item: (
            (0, STARTS_FIRST.index(item.path.name))
            if item.path.name in STARTS_FIRST
            else (1, -weight.get(item.path.name, 0.0))
        )
    )


def pytest_sessionfinish(session) -> None:
    """Under pytest-xdist (CI: ``-n auto``) a worker hands its fuzz counts to the controller,
    which prints the summary."""
    import sys

    support = sys.modules.get("fuzz_support")
    out = getattr(session.config, "workeroutput", None)  # set in xdist workers only
    if out is not None and support is not None:
        out["fuzz_outcomes"] = {t: dict(c) for t, c in support.OUTCOMES.items()}


@pytest.hookimpl(optionalhook=True)  # an xdist hook: pytest without xdist knows it not
def pytest_testnodedown(node, error) -> None:
    """The controller adds up the fuzz counts of a worker that finished."""
    outcomes = getattr(node, "workeroutput", {}).get("fuzz_outcomes")
    if outcomes:
        import fuzz_support

        for target, counts in outcomes.items():
            fuzz_support.OUTCOMES[target].update(counts)


def pytest_terminal_summary(terminalreporter) -> None:
    """The fuzz suite's counts (inputs tried per target and how they ended), when it ran."""
    import sys

    support = sys.modules.get("fuzz_support")
    lines = support.summary_lines() if support is not None else []
    if lines:
        terminalreporter.section("fuzz inputs and outcomes")
        for line in lines:
            terminalreporter.write_line(line)
