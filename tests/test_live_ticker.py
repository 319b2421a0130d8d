"""The per-tick detector reproduces ``detect`` sample by sample; the row ring."""

from __future__ import annotations

import numpy as np
import pytest
from live_support import assert_same_events, tick_recording
from naive_frames import recording_from_candump

from monitor.config.settings import load_config
from monitor.detection.offline import detect
from monitor.detection.ticker import Ticker
from monitor.io.recording import Recording
from monitor.resources import resource_path
from monitor.sampling.ring import RowRing

CFG = load_config()


def test_ring_last_rows_are_contiguous_and_ordered() -> None:
    ring = RowRing(3, 2)
    assert np.isnan(ring.last(3)).all()
    for k in range(7):
        ring.push(np.array([k, -k], dtype=float))
        w = ring.last(min(k + 1, 3))
        assert w.flags.c_contiguous
        assert w[-1, 0] == k
        assert list(w[:, 0]) == list(range(k + 1 - w.shape[0], k + 1))
    with pytest.raises(ValueError):
        ring.last(4)


@pytest.mark.parametrize("log", ["spool_wear.log", "piston_wear.log"])
def test_ticks_give_the_events_of_detect(model, log: str) -> None:
    rec = recording_from_candump(resource_path("replay", log))
    det = detect(model, rec, CFG.alarm, CFG.horizon)
    js, events = tick_recording(Ticker(model, CFG.alarm, CFG.horizon), rec)
    assert_same_events(events, det)
    assert any(e["state"] == "fault" for e in events)
    ok = np.isfinite(det.j)
    assert np.array_equal(ok, np.isfinite(js))
    np.testing.assert_allclose(js[ok], det.j[ok], rtol=1e-9)


def test_gated_rows_match_detect(model) -> None:
    """Engine off and a missing sensor are gated exactly as offline: inactive, sensor fault,
    the window held, and the same events."""
    rec = recording_from_candump(resource_path("replay", "normal.log"))
    cols = {k: v.copy() for k, v in rec.columns.items()}
    cols["EngineSpeed"][2000:2600] = 0.0  # machine off for 6 s
    cols["PA"][4000:4150] = np.nan  # one sensor silent 1.5 s
    cols["QP"][5000:5001] = np.nan  # a single stale sample
    cols["EngineSpeed"][6000:6100] = np.nan  # commands stale < silent_settle_s: engine off
    rec2 = Recording(rec.t, cols, "edited", dict(rec.meta))
    det = detect(model, rec2, CFG.alarm, CFG.horizon)
    js, events = tick_recording(Ticker(model, CFG.alarm, CFG.horizon), rec2)
    assert_same_events(events, det)
    states = [e["state"] for e in events]
    assert "inactive" in states and "sensor_fault" in states and "fault" not in states
    np.testing.assert_allclose(js, det.j, rtol=1e-9)
