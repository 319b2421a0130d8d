"""The statistics as one family (monitor.model.statistic): a fifth statistic defined and
registered in this module alone is carried by the ticker, `monitor detect` (its level, its
summary and the ``statistics`` entry), the model file and its checks, and training, with no
other file changed; and the summary says per statistic whether it was on and why."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

from monitor.errors import ModelFileError
from monitor.io.recording import Recording
from monitor.model.statistic import HeldOut, Statistic, register, registry, unregister
from monitor.model.threshold import ThresholdRule


@dataclass(frozen=True)
class ShiftModel:
    """What the fifth statistic keeps in the model file."""

    window_n: int
    scale: float  # z-units: the largest held-out |window mean| of the first output
    m0: float = float("nan")

    def to_dict(self) -> dict[str, Any]:
        return {"window_n": self.window_n, "scale": self.scale, "m0": self.m0}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ShiftModel:
        return cls(int(d["window_n"]), float(d["scale"]), float(d["m0"]))


class _ShiftWindow:
    """|mean of the first output's residual| over the last ``window_n`` valid samples, by
    a plain running sum (no resummation: the test's windows are short)."""

    def __init__(self, params: ShiftModel) -> None:
        self.p = params
        self.ring = np.zeros(params.window_n)
        self.pos, self.count, self.total = 0, 0, 0.0

    def step(self, e: np.ndarray, row: np.ndarray) -> float:
        if not np.all(np.isfinite(e)):
            return float("nan")
        v = float(e[0])
        self.total += v - self.ring[self.pos]
        self.ring[self.pos] = v
        self.pos = (self.pos + 1) % self.p.window_n
        self.count = min(self.count + 1, self.p.window_n)
        if self.count < self.p.window_n:
            return float("nan")
        return abs(self.total / self.p.window_n) / self.p.scale


class Shift(Statistic):
    """M: the first output's windowed mean residual over its held-out largest."""

    name = "M"
    key = "shift"
    threshold_key = "m0"
    title = "mean-shift statistic M"

    def __init__(self, window_n: int = 500) -> None:
        self.window_n_setting = window_n

    def unscaled(self, held: HeldOut) -> ShiftModel:
        unit = ShiftModel(self.window_n_setting, 1.0)
        tops = [np.nanmax(s) for e in held.residuals if np.isfinite(s := _series(unit, e)).any()]
        return ShiftModel(self.window_n_setting, float(max(tops)))

    def series(self, e: np.ndarray, rec: Recording) -> np.ndarray:
        return _series(self.params_, e)

    def window(self, columns: Sequence[str], n_out: int) -> _ShiftWindow:
        return _ShiftWindow(self.params_)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ShiftModel:
        return ShiftModel.from_dict(d)


def _series(params: ShiftModel, e: np.ndarray) -> np.ndarray:
    w = _ShiftWindow(params)
    return np.array([w.step(row, row) for row in np.asarray(e, dtype=np.float64)])


@pytest.fixture
def shift():
    """M registered for one test, removed afterwards."""
    register(Shift)
    yield Shift
    unregister(Shift.name)


@pytest.fixture(scope="module")
def normal_e(model):
    """The shipped normal log and the shipped model's residuals over it, as detect gates them."""
    from monitor.config.settings import load_config
    from monitor.detection.offline import detect
    from monitor.resources import resource_path
    from monitor.sampling.read import read_recording

    cfg = load_config()
    rec = read_recording(resource_path("replay", "normal.log"))
    return rec, detect(model, rec, cfg.alarm, cfg.horizon, gating=cfg.gating).residual


def _with_shift(model, normal_e, factor: float = 2.0):
    """The shipped model with M fitted on the normal log (``factor`` x its largest value)."""
    rec, e = normal_e
    stat = Shift().fit(HeldOut([e], [rec], model.spec.outputs), ThresholdRule(factor=factor))
    m = dataclasses.replace(model, statistics={})
    Shift.put(m, stat.params_)
    return m, stat


def test_members_in_order() -> None:
    """J, B, L and H are the family, J first: the level rests on it."""
    assert [s.name for s in registry()][:4] == ["J", "B", "L", "H"]


def test_fit_sets_the_threshold_by_the_rule(shift, model, normal_e) -> None:
    """Base-class work: the scale is the held-out maximum, so the held-out M peaks at 1 and
    the max rule with factor 2 sets m0 = 2; support counts the held-out data judged."""
    _, stat = _with_shift(model, normal_e)
    assert stat.threshold_ == pytest.approx(2.0, rel=1e-12)
    rec, e = normal_e
    judged = np.isfinite(_series(stat.params_, e)).sum()
    assert stat.support_["judged_h"] == pytest.approx(judged * 0.01 / 3600, abs=1e-4)
    assert stat.support_["windows"] == int(
        np.sum(
            np.isfinite(_series(stat.params_, e))[: len(e) // 500 * 500].reshape(-1, 500).sum(1)
            >= 250
        )
    )


def test_detect_and_ticker_carry_a_fifth_statistic(shift, model, normal_e) -> None:
    """With a threshold below the normal log's M, M alone raises the alarm (J and the others
    stay below theirs on normal data), offline and live alike, and the summary has its keys
    and its entry."""
    from live_support import assert_same_events, rows_of

    from monitor.config.settings import load_config
    from monitor.detection.offline import detect
    from monitor.detection.ticker import Ticker, event

    cfg = load_config()
    rec, _ = normal_e
    m, stat = _with_shift(model, normal_e, factor=0.5)  # m0: half the log's largest M
    plain = detect(model, rec, cfg.alarm, cfg.horizon, gating=cfg.gating)
    det = detect(m, rec, cfg.alarm, cfg.horizon, gating=cfg.gating)
    assert not plain.summary["alarm"] and det.summary["alarm"]
    s = det.summary
    assert s["max_M"] == pytest.approx(1.0, rel=1e-9)  # the held-out largest is the scale
    assert s["shift_threshold"] == stat.threshold_
    assert s["max_level"] == pytest.approx(max(plain.summary["max_level"], 2.0), rel=1e-9)
    assert s["statistics"]["M"]["on"] is True
    assert s["statistics"]["M"]["threshold"] == stat.threshold_
    assert plain.summary["max_M"] is None and not plain.summary["statistics"]["M"]["on"]
    json.dumps(s)  # the summary file stays JSON
    ticker = Ticker(m, cfg.alarm, cfg.horizon, gating=cfg.gating)
    ms, events = np.empty(len(rec)), []
    for i, row in enumerate(rows_of(rec)):
        tick = ticker.tick(row)
        ms[i] = ticker.value("M")
        if tick.changed:
            events.append(event(tick, ticker.fault, ticker.eps0, rec.meta.get("start_time_s")))
    ok = np.isfinite(det.series["M"])
    assert np.array_equal(np.isnan(ms), ~ok) and ok.sum() > 1000
    np.testing.assert_allclose(ms[ok], det.series["M"][ok], rtol=1e-9)
    assert_same_events(events, det)


def test_model_file_round_trip_and_checks(shift, model, normal_e, tmp_path) -> None:
    """M's section goes into the header and back; a NaN threshold is refused by name; a
    monitor that does not know M still loads the file (and judges without M)."""
    from monitor.model.modelfile import load_model, save_model

    m, stat = _with_shift(model, normal_e)
    path = tmp_path / "m.model.npz"
    save_model(path, m)
    back = load_model(path)
    assert back.statistics["shift"] == stat.params_
    assert back.bias.to_dict() == model.bias.to_dict() and back.eps0 == model.eps0
    bad = dataclasses.replace(m, statistics={"shift": ShiftModel(500, 1.0, float("nan"))})
    save_model(tmp_path / "bad.model.npz", bad)
    with pytest.raises(ModelFileError, match="m0 must be a finite number"):
        load_model(tmp_path / "bad.model.npz")
    unregister("M")
    assert load_model(path).statistics == {}


def test_training_fits_a_registered_statistic(shift) -> None:
    """`monitor train` fits every member: M's threshold, note and support land in the model."""
    from monitor.sim.cycles import make_cycle
    from monitor.sim.machine import load_machine
    from monitor.sim.simulate import simulate
    from monitor.training.settings import (
        DGRNNSettings,
        IsolationSettings,
        StatisticSettings,
        TrainConfig,
    )
    from monitor.training.train import train

    runs = [simulate(make_cycle("boom", 60.0, s), load_machine(), seed=s) for s in range(1, 10)]
    said: list[str] = []
    cfg = TrainConfig(
        DGRNNSettings(max_patterns=300),
        statistics=StatisticSettings(bias=False),
        isolation=IsolationSettings("none"),
    )
    # Eight minutes held out: 88 windows of 5 s (36 independent), and a threshold set on the
    # cooler half holds on the warmer (0.71 x) and back.
    m = train(runs[:1], cfg, said.append, held_out=runs[1:])
    params = m.statistics["shift"]
    assert params.m0 == pytest.approx(2.0, rel=1e-12)
    assert m.training["shift"] == "on" and m.training["support"]["M"]["parts"] == 8
    assert m.training["support"]["M"]["independent_windows"] >= 8
    assert m.training["support"]["M"]["transfer"]["ratio"] < 1
    assert any("mean-shift statistic M over 5 s, m0 2: " in line for line in said)
    # 45 s held out (8 windows, fewer independent) is too little: off, saying why and what
    # switch it on.
    brief = simulate(make_cycle("boom", 45.0, 4), load_machine(), seed=4)
    short = train(runs[:3], cfg, said.append, held_out=[brief])
    assert "shift" not in short.statistics
    assert short.training["shift"].startswith("off: its threshold rests on ")
    assert "more held-out normal data" in short.training["shift"]


def test_summary_says_which_statistics_were_on_and_why(model) -> None:
    """The shipped model: all four on with their thresholds, support from what the model
    file knows (held out, 120 parts, the rule); F, newer than the file, off as not in it;
    a model without B says it is off and why."""
    from monitor.model.statistic import statistics_entries

    entries = statistics_entries(model)
    assert list(entries) == ["J", "B", "L", "H", "F"]
    assert [entries[n]["threshold"] for n in "JBLH"] == [
        model.eps0,
        model.bias.b0,
        model.lever.l0,
        model.hold.h0,
    ]
    assert all(entries[n]["on"] for n in "JBLH")
    assert entries["F"] == {
        "on": False,
        "threshold": None,
        "why": "off: not in this model file",
        "support": {},
    }
    assert entries["B"]["support"] == {
        "validation": "held out",
        "parts": 120,
        "rule": "2 x the max of held-out normal values",
    }
    off = dataclasses.replace(model, bias=None, training=dict(model.training, bias="off: short"))
    assert statistics_entries(off)["B"] == {
        "on": False,
        "threshold": None,
        "why": "off: short",
        "support": {},
    }


def test_eval_sim_and_fleet_carry_a_fifth_statistic(shift, model, normal_e, tmp_path) -> None:
    """eval-sim's run score and the fleet's logs table get M's peak ratio, read from the very
    summary `monitor detect` writes; a model without M gives null."""
    import pyarrow.parquet as pq

    from monitor.evaluation.sim_eval import RunSpec, score_run
    from monitor.fleet.pipeline import judge_log, model_to_bytes
    from monitor.fleet.store import ResultStore
    from monitor.resources import resource_path

    m, stat = _with_shift(model, normal_e)
    log = str(resource_path("replay", "normal.log"))
    judged = judge_log(model_to_bytes(m), log)
    s = judged.row
    assert s["max_m_ratio"] == pytest.approx(1.0 / stat.threshold_, rel=1e-9)  # max M is 1
    assert judged_without_m(model, log) is None
    store = ResultStore(tmp_path / "results")
    store.add(
        {
            **s,
            "machine": "M01",
            "log": "M01/logs/a.log",
            "sha256": "x",
            "model": "own",
            "error": None,
        },
        judged.events,
    )
    store.compact()
    table = pq.read_table(tmp_path / "results" / "logs.parquet").to_pylist()
    assert table[0]["max_m_ratio"] == pytest.approx(s["max_m_ratio"])
    from monitor.config.settings import load_config
    from monitor.detection.offline import detect

    cfg = load_config()
    det = detect(m, normal_e[0], cfg.alarm, cfg.horizon, gating=cfg.gating)
    run = score_run(det, RunSpec(seed=1, duration_s=90.0))
    assert run["max_M_over_m0"] == pytest.approx(round(1.0 / stat.threshold_, 4))


def judged_without_m(model, log: str) -> float | None:
    from monitor.fleet.pipeline import judge_log, model_to_bytes

    return judge_log(model_to_bytes(model), log).row["max_m_ratio"]
