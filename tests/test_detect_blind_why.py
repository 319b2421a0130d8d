"""benchmarks.detect_blind_why: J's window at a false alarm's peak split by output and spool
regime, against shares worked by hand and J itself; whether any threshold separates a fault
run from its machine's normal logs."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.detect_blind_why import (
    largest_level,
    main,
    regime_parts,
    separable,
    separable_by_regime,
    separation_table,
    window_shares,
)
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


def test_largest_level_after_the_onset() -> None:
    """Only what the detector judged at or after the onset counts: 3.0 at 0 s is before it,
    NaN (not judged) is skipped; nothing judged after it is None, never 0."""
    level = np.array([3.0, np.nan, 0.5, 0.7, np.nan])
    t = np.arange(5.0)
    assert largest_level(level, t, 2.0) == 0.7
    assert largest_level(level, t, 0.0) == 3.0
    assert largest_level(level, t, 4.0) is None
    assert largest_level(None, t, 0.0) is None


def test_separable_worked_by_hand() -> None:
    """Above every judged normal log is separable; equal to the largest is not (no threshold
    lies strictly between); a run never judged is not; with no normal log judged any judged
    run is."""
    normal = [0.4, None, 0.9]
    assert separable(normal, 1.0)
    assert not separable(normal, 0.9)
    assert not separable(normal, 0.5)
    assert not separable(normal, None)
    assert separable([None, None], 0.1)


def test_regime_parts_worked_by_hand() -> None:
    """N = 2, the window ending at sample 4 (judged samples 1, 3, 4; e^2 [0, 4] lower,
    [1, 1] and [9, 0] holds) over 3 samples x 2 outputs: hold 11/6, raise 0, lower 4/6,
    adding up to J = 15/6; sample 2 (not judged) is NaN in every part."""
    parts = regime_parts(E, SPOOL, 2)
    np.testing.assert_allclose(parts[:, 4], [11.0 / 6.0, 0.0, 4.0 / 6.0], rtol=1e-12)
    np.testing.assert_allclose(parts.sum(axis=0), window_j(E, 2), rtol=1e-12)
    assert np.isnan(parts[:, 2]).all()


def test_separable_by_regime_worked_by_hand() -> None:
    """Normal logs reach hold 0.5, raise 1.0, lower never judged: a run at raise 0.9 and
    hold 0.6 is separable by its hold part (above 0.5), one at hold 0.4 and raise 1.0 is not,
    any judged lower part is (no normal log judged there)."""
    normal = [[0.5, 0.2, None], [0.1, 1.0, None]]
    assert separable_by_regime(normal, [0.6, 0.9, None])
    assert not separable_by_regime(normal, [0.4, 1.0, None])
    assert separable_by_regime(normal, [None, None, 0.01])
    assert not separable_by_regime(normal, [None, None, None])


def test_separation_table_counts_by_type_and_severity() -> None:
    """Two machines: pm05's normal logs reach 1.2 (hold 1.0, raise 0.3), its faults 1.5 (yes,
    and by its hold part 1.4) and 0.8 (no; by regime yes, raise 0.5 > 0.3); pm15's reach
    0.6 and its one fault was not judged (no, no): pm05 0.3 1/1 1/1, pm05 0.5 0/1 1/1, pm15
    0.3 0/1 0/1."""

    def e(sev: float) -> dict:
        return {"severity": sev}

    found = {
        "types/pm05/pm05_m0": {
            "normal": {
                "n000": (e(0.0), 1.2, [1.0, 0.3, 0.1]),
                "n001": (e(0.0), None, [None, None, None]),
            },
            "fault": {
                "piston_wear_0.30_00": (e(0.3), 1.5, [1.4, 0.1, 0.0]),
                "spool_wear_0.50_00": (e(0.5), 0.8, [0.2, 0.5, 0.1]),
            },
        },
        "types/pm15/pm15_m0": {
            "normal": {"n000": (e(0.0), 0.6, [0.3, 0.2, 0.1])},
            "fault": {"spool_stroke_0.30_00": (e(0.3), None, [None, None, None])},
        },
    }
    text = separation_table(found)
    assert "| types/pm05/pm05_m0 | 1.20 (n000) | piston_wear_0.30_00 | 1.50 | yes | yes |" in text
    assert "| types/pm05/pm05_m0 | 1.20 (n000) | spool_wear_0.50_00 | 0.80 | no | yes |" in text
    assert (
        "| types/pm15/pm15_m0 | 0.60 (n000) | spool_stroke_0.30_00 | not judged | no | no |" in text
    )
    assert text.endswith(
        "| pm05 | 0.3 | 1/1 | 1/1 |\n| pm05 | 0.5 | 0/1 | 1/1 |\n| pm15 | 0.3 | 0/1 | 0/1 |\n"
    )
