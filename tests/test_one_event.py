"""Which commissioning minute a threshold rests on: ``monitor.model.threshold.one_event``
on J series built by hand, and the fleet page's note beside the machine's model."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from monitor.cli import main
from monitor.fleet.store import LOG_SCHEMA
from monitor.model.modelfile import load_model, save_model
from monitor.model.threshold import ONE_EVENT_RATIO, one_event
from monitor.resources import resource_path

BLOCK = 100


def _series(block_max: list[float]) -> np.ndarray:
    """A J series whose blocks of BLOCK samples peak at the given values (a ramp to each)."""
    return np.concatenate([np.linspace(0.1 * m, m, BLOCK) for m in block_max])


def test_one_block_far_above_the_rest_is_named_with_its_place_and_ratio():
    # Ten blocks peaking at 1.0 but one at 1.5 and one (block 6) at 8.0: 8.0 / 1.5 = 5.33.
    peaks = [1.0] * 10
    peaks[2], peaks[6] = 1.5, 8.0
    j = _series(peaks)
    j[:30] = np.nan  # the window's warm-up
    got = one_event([j], BLOCK)
    assert got is not None
    assert got["part"] == 0 and got["start"] == 6 * BLOCK and got["j"] == 8.0
    assert np.isclose(got["ratio"], 8.0 / 1.5)


def test_an_event_spanning_two_blocks_is_one_event_and_two_events_are_none():
    # A J window spans neighbouring blocks: 8.0 then 7.5 is one event (ratio 8 against the
    # 1.0 elsewhere); the same peak repeated far away is a second event: nothing stands out.
    peaks = [1.0] * 10
    peaks[4], peaks[5] = 8.0, 7.5
    assert np.isclose(one_event([_series(peaks)], BLOCK)["ratio"], 8.0)
    peaks[9] = 7.9
    assert one_event([_series(peaks)], BLOCK) is None


def test_the_ratio_rule_and_parts_of_several_recordings():
    # Just below the ratio: no note; just above: the note names the second recording.
    below = [1.0, 1.0, 1.0, ONE_EVENT_RATIO * 0.99]
    assert one_event([_series([1.0] * 4), _series(below)], BLOCK) is None
    above = [1.0, 1.0, 1.0, ONE_EVENT_RATIO * 1.01]
    got = one_event([_series([1.0] * 4), _series(above)], BLOCK)
    assert got is not None and got["part"] == 1 and got["start"] == 3 * BLOCK
    # The last block of one recording and the first of the next are not neighbours.
    edge = one_event([_series([1.0, 1.0, 1.0, 9.0]), _series([8.5, 1.0, 1.0])], BLOCK)
    assert edge is None


def test_the_fleet_page_says_which_machine_rests_on_one_event(tmp_path):
    results = tmp_path / "results"
    (results / "models").mkdir(parents=True)
    model = load_model(resource_path("config", "boom_default.model.npz"))
    plain = load_model(resource_path("config", "boom_default.model.npz"))
    model.training = dict(
        model.training,
        threshold_one_event={
            "source": "/data/fleet/M01/commissioning/normal.log",
            "t_s": 570.0,
            "j": 8.3e-3,
            "ratio": 6.4,
        },
    )
    save_model(results / "models" / "M01.model.npz", model)
    save_model(results / "models" / "M02.model.npz", plain)
    rows = []
    for mid in ("M01", "M02"):
        for i in range(4):
            r = {name: None for name in LOG_SCHEMA.names}
            r |= {
                "machine": mid,
                "log": f"{mid}/logs/day{i:02d}.log",
                "sha256": f"{mid}{i}",
                "verdict": "healthy",
                "alarm": False,
                "sensor_fault": False,
                "max_j_ratio": 0.3,
                "p95_j_ratio": 0.2,
                "model": "commissioned",
            }
            rows.append(r)
    pq.write_table(pa.Table.from_pylist(rows, schema=LOG_SCHEMA), results / "logs.parquet")
    assert main(["fleet", "report", str(results), "--out", str(tmp_path / "page")]) == 0
    table = (tmp_path / "page" / "fleet.md").read_text()
    m01 = next(line for line in table.splitlines() if line.startswith("| M01 "))
    m02 = next(line for line in table.splitlines() if line.startswith("| M02 "))
    assert m01.endswith(
        "| commissioned; J0 rests on one event (6.4 x any other window's, normal.log at 9.5 min) |"
    )
    assert m02.endswith("| commissioned |")
