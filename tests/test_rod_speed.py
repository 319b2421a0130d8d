"""RodSpeed: the rod's speed, derived from RodPos (``monitor.signals.ROD_SPEED``).

A piston leak passes part of the section's flow across the piston, so the rod moves slower
for the same flow; a section model trained with ``--rod-speed`` predicts the speed and its
full-lever statistic L watches it.  No bus or CSV carries the speed: it is RodPos's travel
over the last ten rows (0.1 s), either way, read the same way offline and per tick.
"""

from __future__ import annotations

import numpy as np
import pytest

from monitor.errors import ConfigError, InputFileError
from monitor.io.recording import Recording
from monitor.model.spec import DGRNNSpec


def _rec(pos_mm: np.ndarray) -> Recording:
    n = len(pos_mm)
    return Recording(np.arange(n) * 0.01, {"RodPos": np.asarray(pos_mm, dtype=float)})


def test_rod_speed_is_the_rods_travel_over_a_tenth_of_a_second_either_way() -> None:
    # 1 mm a row out for 30 rows, then 2 mm a row back: 100 mm/s out, 200 mm/s back.
    pos = np.concatenate((np.arange(31.0), 30.0 - 2.0 * np.arange(1, 21)))
    rec = _rec(pos)
    assert rec.has("RodSpeed") and "RodSpeed" not in rec.columns  # derived, never stored
    v = rec["RodSpeed"]
    assert v.shape == pos.shape
    # The first rows reach back to the first row: row 4 has moved 4 mm in "0.1 s".
    assert v[0] == 0.0 and v[4] == pytest.approx(40.0)
    assert v[10:31] == pytest.approx(np.full(21, 100.0))
    # Row 35 is 5 rows back in: 30 - 10 = 20 mm now, 25 mm ten rows before: 50 mm/s.
    assert v[35] == pytest.approx(50.0)
    assert v[41:] == pytest.approx(np.full(10, 200.0))


def test_a_missing_rod_position_is_a_missing_speed_for_ten_rows() -> None:
    pos = np.arange(40.0)
    pos[20] = np.nan
    v = _rec(pos)["RodSpeed"]
    assert np.flatnonzero(np.isnan(v)).tolist() == [20, 30]


def test_a_recording_without_rod_position_has_no_speed() -> None:
    rec = Recording(np.arange(3) * 0.01, {"PA": np.zeros(3)})
    assert not rec.has("RodSpeed")
    with pytest.raises(InputFileError, match="RodSpeed"):
        rec["RodSpeed"]


def test_the_section_preset_predicts_the_rod_speed_from_the_flow_not_its_own_past() -> None:
    spec = DGRNNSpec.preset("section", neighbours=("SpoolCmd@boom",), rod_speed=True)
    plain = DGRNNSpec.preset("section", neighbours=("SpoolCmd@boom",))
    assert spec.outputs == (*plain.outputs, "RodSpeed")
    assert spec.features == plain.features  # the same inputs: RodSpeed is never one
    assert DGRNNSpec.from_dict(spec.to_dict()) == spec
    with pytest.raises(ConfigError, match="section preset"):
        DGRNNSpec.preset("default", rod_speed=True)
