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
