"""benchmarks.detect_blind_why: J's window at a false alarm's peak split by output and spool
regime, against shares worked by hand and J itself."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.detect_blind_why import main, window_shares
from monitor.model.residual import window_j

# Two outputs; a NaN pauses J's window (sample 2 is not judged).  Lever: raise, lower, and
# three holds (3 % is inside the +-5 % band).
E = np.array([[1.0, 0.0], [0.0, 2.0], [np.nan, 1.0], [1.0, 1.0], [3.0, 0.0]])
SPOOL = np.array([10.0, -10.0, 0.0, 0.0, 3.0])


def test_shares_worked_by_hand() -> None:
    """N = 2: the window ending at sample 4 holds the judged samples 1, 3 and 4, e^2
    [0, 4] (lower), [1, 1] and [9, 0] (holds): 15 in all, so hold 10/15 and 1/15, lower
    0 and 4/15; ending at 3 it holds 0, 1 and 3: raise [1, 0], lower [0, 4], hold [1, 1]
    over 7."""
    got = window_shares(E, SPOOL, 4, 2)
    want = np.array([[10.0, 1.0], [0.0, 0.0], [0.0, 4.0]]) / 15.0
    np.testing.assert_allclose(got, want, rtol=1e-12)
    got = window_shares(E, SPOOL, 3, 2)
    want = np.array([[1.0, 1.0], [1.0, 0.0], [0.0, 4.0]]) / 7.0
    np.testing.assert_allclose(got, want, rtol=1e-12)


def test_the_window_is_js() -> None:
    """The samples split are those J averaged: 15 over 3 samples and 2 outputs is J at
    sample 4 (eq. 9 as the detector computes it)."""
    assert window_j(E, 2)[4] == pytest.approx(15.0 / 6.0, rel=1e-12)


def test_unscored_folder_is_one_line(tmp_path, capsys) -> None:
    assert main(["--work", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "data/key.json" in err


def test_no_alarm_is_said(tmp_path, capsys) -> None:
    """A scored seed whose normal logs were all quiet: one line saying so, exit 0."""
    import json

    entry = {"path": "types/pm05/pm05_m0/normal/n000.csv", "kind": "normal"}
    (tmp_path / "data").mkdir()
    (tmp_path / "data" / "key.json").write_text(json.dumps({"files": [entry]}))
    summary = tmp_path / "detect" / "types/pm05/pm05_m0/normal/n000.summary.json"
    summary.parent.mkdir(parents=True)
    summary.write_text(json.dumps({"alarm": False}))
    assert main(["--work", str(tmp_path)]) == 0
    assert capsys.readouterr().out == f"no normal log in {tmp_path} alarmed\n"
