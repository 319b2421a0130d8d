"""The pump rule (monitor.detection.pump, monitor.training.pump, monitor.model.pumplaw) on
synthetic rows whose pump obeys a known margin law: the law is recovered, the counted
samples are the ones the command schedule says, a known offset is found and a healthy run
is not, and a threshold the held-out data cannot support is off with its reason."""

from __future__ import annotations

import functools
import json
from pathlib import Path

import numpy as np
import pytest

from monitor.detection.alarm import State
from monitor.detection.pump import PumpColumns, PumpRule, judge_rows
from monitor.errors import ModelFileError
from monitor.model.pumplaw import PumpModel, load_pump_model, save_pump_model
from monitor.training.pump import FACTOR, fit_pump

# The law the synthetic pump obeys (the whole machine's physics: band 5 bar over a full
# flow of 39.6 L/min, healthy leakage 0.010 L/min per bar).
A, B, C = 5 / 39.6, 5 * 0.010 / 39.6, 0.0
MARGIN = 20.0
STEP_S = 5.0
COLUMNS = ("PP", *(f"{s}_{c}" for s in ("S1", "S2") for c in ("SpoolCmd", "PA", "PB", "QP")))
COLS = PumpColumns.of(
    COLUMNS, "PP", [{c: f"{s}_{c}" for c in ("SpoolCmd", "PA", "PB", "QP")} for s in ("S1", "S2")]
)


def _rows(
    seed: int,
    duration_s: float,
    offset_bar: float = 0.0,
    from_s: float = 0.0,
    only_s1: bool = False,
) -> tuple[np.ndarray, int]:
    """Rows of two sections whose spools step every 5 s, and the number of samples that
    count by the schedule (a section open, both spools unchanged for 0.5 s)."""
    rng = np.random.default_rng(seed)
    n = int(duration_s * 100)
    t = np.arange(n) * 0.01
    steps = int(np.ceil(duration_s / STEP_S))
    s1 = rng.choice([0.0, 20.0, 40.0, 70.0, -30.0, -60.0], steps)
    s2 = rng.choice([0.0, 0.0, 50.0, -50.0], steps)
    k = (t // STEP_S).astype(int)
    spool1, spool2 = s1[k], s2[k]
    load = rng.uniform(40.0, 160.0, (4, steps))[:, k]  # PA1, PB1, PA2, PB2
    flow1, flow2 = 0.3 * np.abs(spool1), 0.2 * np.abs(spool2)
    pls = np.maximum.reduce(
        [
            np.where(spool1 > 5, load[0], 0.0),
            np.where(spool1 < -5, load[1], 0.0),
            np.where(spool2 > 5, load[2], 0.0),
            np.where(spool2 < -5, load[3], 0.0),
        ]
    )
    flow = flow1 + flow2
    off = np.where(t >= from_s, offset_bar, 0.0)
    if only_s1:  # a fault of section 1 that costs margin only while it is open
        off = np.where(np.abs(spool1) > 5, off, 0.0)
    # PLS + margin - PP = A flow + B PP + C + offset, solved for PP, plus sensor noise.
    pp = (pls + MARGIN - A * flow - C - off) / (1 + B) + rng.normal(0, 0.3, n)
    rows = np.column_stack(
        [t, pp, spool1, load[0], load[1], flow1, spool2, load[2], load[3], flow2]
    )
    # Counted by the schedule: from 0.5 s after a step that changed a spool (the first
    # step included) on, the whole of a step that changed none.
    changed = np.r_[True, (np.diff(s1) != 0) | (np.diff(s2) != 0)][k]
    into_step = np.round(t - k * STEP_S, 6)
    counted = ((into_step >= 0.5) | ~changed) & ((np.abs(spool1) > 5) | (np.abs(spool2) > 5))
    return rows, int(counted.sum())


@functools.cache
def _model(held: int = 4, held_s: float = 600.0) -> PumpModel:
    fits = [_rows(s, 600.0)[0] for s in (1, 2)]
    helds = [_rows(s, held_s)[0] for s in range(10, 10 + held)]
    return fit_pump(fits, helds, COLS, MARGIN)


def test_the_law_is_recovered_from_normal_rows() -> None:
    law = _model().law
    assert law.flow_coef == pytest.approx(A, abs=0.002)
    assert law.pp_coef == pytest.approx(B, abs=0.0005)
    assert law.offset_bar == pytest.approx(C, abs=0.1)


def test_counted_samples_are_the_schedules() -> None:
    rows, counted = _rows(5, 300.0)
    rule = PumpRule(_model(), COLS)
    for row in rows.tolist():
        rule.tick(row)
    assert rule.counted == counted


def test_a_known_offset_is_found_and_a_healthy_run_is_not() -> None:
    model = _model()
    assert model.on and model.threshold_bar is not None
    # Healthy rows' window means are noise: 0.3 bar / sqrt(2000) ~ 0.007 bar; the
    # threshold is FACTOR x the largest of them, far below the 0.3 bar offset.
    assert model.threshold_bar < 0.1
    worn, _ = _rows(99, 600.0, offset_bar=0.3, from_s=200.0)
    det = judge_rows(model, COLS, worn)
    s = det.summary
    assert s["alarm"] and s["fault"] == "pump_wear" and s["verdict"] == "fault"
    # Raised once the window holds enough worn samples: after the onset, within two windows'
    # worth of real time (20 s counted of ~0.7 counted per second).
    assert 200.0 < s["first_alarm_t"] < 200.0 + 2 * 20.0 / 0.6
    assert s["max_margin_residual_bar"] == pytest.approx(0.3 / (1 + B), abs=0.03)
    healthy = judge_rows(model, COLS, _rows(98, 600.0)[0]).summary
    assert healthy["verdict"] == "healthy" and not healthy["alarm"]


def test_an_excess_only_one_section_carries_is_not_the_pumps() -> None:
    model = _model()
    # 0.5 bar short of margin while section 1 is open (as a leaking boom piston that draws
    # the pump to its limit): the window's mean is far above the threshold, but section 1's
    # closed samples show nothing.
    rows, _ = _rows(95, 600.0, offset_bar=0.5, from_s=100.0, only_s1=True)
    rule = PumpRule(model, COLS)
    carried = set()
    for row in rows.tolist():
        rule.tick(row)
        if rule.stat_bar > 2 * (model.threshold_bar or 0.0):
            carried.add(rule.carried_by)
    # Windows in which section 1 was hardly closed cannot tell (None); none says pump.
    assert "section 1" in carried and carried <= {"section 1", None}
    s = judge_rows(model, COLS, rows).summary
    assert not s["alarm"] and s["verdict"] == "healthy"
    assert s["max_margin_residual_bar"] > 2 * (model.threshold_bar or 0.0)


def test_the_live_rule_gives_the_offline_events() -> None:
    model = _model()
    worn, _ = _rows(97, 400.0, offset_bar=0.5, from_s=150.0)
    rule = PumpRule(model, COLS)
    live = []
    for row in worn:  # one numpy row at a time, as the daemon's sampler gives them
        if rule.tick(row.tolist()):
            live.append(rule.event(float(row[0]), None, float(worn[0, 0])))
    assert live == judge_rows(model, COLS, worn).events
    assert [e["state"] for e in live] == ["normal", "fault"]
    assert rule.state is State.FAULT and live[-1]["window_from_t"] < live[-1]["t"]


def test_thin_held_out_data_switches_the_rule_off_with_a_reason() -> None:
    one = _model(held=1)
    assert one.threshold_bar is None and "one recording" in (one.off_reason or "")
    short = _model(held=2, held_s=60.0)
    assert short.threshold_bar is None and "independent windows" in (short.off_reason or "")
    det = judge_rows(short, COLS, _rows(96, 300.0, offset_bar=1.0)[0])
    assert det.summary["verdict"] == "not_judged" and not det.events
    assert "off" in det.summary["not_judged_why"]


def test_the_threshold_is_the_factor_over_the_held_out_peak(tmp_path: Path) -> None:
    model = _model()
    sup = model.support
    assert model.threshold_bar == pytest.approx(FACTOR * sup["held_out_max_bar"], rel=1e-3)
    assert sup["sessions"] == 4 and sup["independent_windows"] >= 8
    path = tmp_path / "pump.json"
    save_pump_model(model, path)
    assert load_pump_model(path) == model


@pytest.mark.parametrize(
    ("edit", "says"),
    [
        (lambda d: d.update(kind="model"), "not a pump model"),
        (lambda d: d.update(version=9), "version 9"),
        (lambda d: d["law"].update(flow_coef="x"), "law.flow_coef"),
        (lambda d: d.update(threshold_bar=-1.0), "threshold_bar"),
        (lambda d: d.pop("counting"), "counting"),
    ],
)
def test_a_bad_pump_model_file_is_one_error(tmp_path: Path, edit, says) -> None:
    path = tmp_path / "pump.json"
    save_pump_model(_model(), path)
    data = json.loads(path.read_text())
    edit(data)
    path.write_text(json.dumps(data))
    with pytest.raises(ModelFileError, match=says):
        load_pump_model(path)
