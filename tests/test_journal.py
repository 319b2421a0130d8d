"""The daemon's log lines go to whatever stderr the process has when they are written."""

from __future__ import annotations

import io
import logging
import sys

from monitor.live.journal import setup_logging


def test_a_line_after_stderr_was_swapped_goes_to_the_new_one(monkeypatch) -> None:
    # A process that swaps stderr (the suite's captures, one test after another) and closes
    # the old one: a handler bound to the first stream would print "--- Logging error ---".
    first, second = io.StringIO(), io.StringIO()
    root = logging.getLogger()
    monkeypatch.setattr(root, "handlers", list(root.handlers))
    monkeypatch.setattr(root, "level", root.level)
    monkeypatch.setattr(sys, "stderr", first)
    setup_logging()
    first.close()
    monkeypatch.setattr(sys, "stderr", second)
    logging.getLogger("monitor.test").info("after the swap")
    assert second.getvalue() == "<6>monitor.test: after the swap\n"
