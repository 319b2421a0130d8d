"""``--cpu-durations=N``: the N tests (setup, call or teardown) that cost the most CPU.

On a machine several people share, ``--durations`` measures the load as much as the test:
CPU-seconds do not.  Counted per phase: this process's user and system time, and that of
the child processes it waited for (a ``monitor`` command run with ``subprocess.run``, a
daemon stopped and reaped); a process left running is not counted.  Under pytest-xdist
each worker measures its own tests and the figure travels to the controller with the
report (``user_properties``)."""

from __future__ import annotations

import os
import resource

import pytest

_KEY = "cpu_s"


def _cpu_s() -> float:
    own = resource.getrusage(resource.RUSAGE_SELF)
    waited = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + waited.ru_utime + waited.ru_stime


def addoption(parser: pytest.Parser) -> None:
    """The option (conftest's ``pytest_addoption`` calls this)."""
    parser.getgroup("terminal reporting").addoption(
        "--cpu-durations",
        type=int,
        default=0,
        metavar="N",
        help="show the N most CPU-costly test phases (this process and the processes it "
        "waited for); 0: off",
    )


def _measured(item: pytest.Item, when: str):  # noqa: ANN202 - a hook wrapper's generator
    start = _cpu_s()
    yield
    item.stash.setdefault(_STASH, {})[when] = _cpu_s() - start


_STASH = pytest.StashKey[dict]()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_setup(item: pytest.Item):  # noqa: ANN201
    yield from _measured(item, "setup")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_call(item: pytest.Item):  # noqa: ANN201
    yield from _measured(item, "call")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_teardown(item: pytest.Item):  # noqa: ANN201
    yield from _measured(item, "teardown")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo):  # noqa: ANN201
    outcome = yield
    spent = item.stash.get(_STASH, {}).get(call.when)
    if spent is not None:
        outcome.get_result().user_properties.append((_KEY, round(spent, 3)))


class Summary:
    """The controller's (or the only process's) collection of the figures, and the table."""

    def __init__(self, count: int) -> None:
        self.count = count
        self.phases: list[tuple[float, str, str]] = []

    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        for key, value in report.user_properties:
            if key == _KEY:
                self.phases.append((float(value), report.when, report.nodeid))

    def pytest_terminal_summary(self, terminalreporter) -> None:  # noqa: ANN001
        tr = terminalreporter
        total = sum(p[0] for p in self.phases)
        load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
        tr.write_sep("=", f"most CPU-costly {self.count} test phases")
        tr.write_line(
            f"{total:.1f} CPU-s in all {len(self.phases)} phases measured (load average "
            f"at the end {load})"
        )
        for spent, when, nodeid in sorted(self.phases, reverse=True)[: self.count]:
            tr.write_line(f"{spent:7.1f} CPU-s {when:<8} {nodeid}")


def configure(config: pytest.Config) -> None:
    """Measure in every process when asked; sum up in the controller (or the only one)."""
    import sys

    count = config.getoption("cpu_durations")
    if count <= 0:
        return
    config.pluginmanager.register(sys.modules[__name__], "cpu_time")
    if not hasattr(config, "workerinput"):
        config.pluginmanager.register(Summary(count), "cpu_time_summary")
