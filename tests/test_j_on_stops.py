"""J leaves out the samples settling on an end stop (monitor.model.endstop.settling_on_stop,
monitor.model.residual): the rule worked by hand, live against batch, J paused there, the
detector's summary saying how long was not judged, and the model file (old files judge every
sample as before)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from live_support import rows_of
from model_support import craft_model, set_key

from monitor.errors import ModelFileError
from monitor.io.recording import Recording
from monitor.model.endstop import SettleTracker, settling_on_stop
from monitor.model.modelfile import load_model, save_model
from monitor.model.residual import STOPS_KEY, J, JModel
from monitor.training.settings import StatisticSettings

# A lift at 50 % with 10 L/min (moving), the rod stalls on the top stop (lever still out,
# 0.2 L/min) for 25 samples, the lever is centred for 30 and held inside the hold band (3 %)
# for 5, then a lowering at -40 % with 8 L/min moves the rod off the stop, and a hold.
SPOOL = [50.0] * 10 + [50.0] * 25 + [0.0] * 30 + [3.0] * 5 + [-40.0] * 10 + [0.0] * 10
QP = [10.0] * 10 + [0.2] * 25 + [0.0] * 30 + [0.0] * 5 + [8.0] * 10 + [0.0] * 10
# By hand (a stall counts at its 20th sample of lever out and QP below 1 L/min, 0.2 s):
# samples 0-9 moving: no; 10-28, the stall's first 19: no; 29-34 stalled: yes; 35-69 the
# hold that follows, in and out of the band: yes; 70-79 the rod moves again: no; 80-89: no.
SETTLING = [False] * 29 + [True] * 41 + [False] * 20


def test_settling_worked_by_hand() -> None:
    got = settling_on_stop(np.array(SPOOL), np.array(QP))
    assert got.tolist() == SETTLING


def test_a_short_stall_or_a_gap_in_it_is_no_stop() -> None:
    """A reversal passing through low flow for less than 0.2 s is no stall; a NaN inside a
    stall starts its count again (19 + 19 samples: never 20 in a row)."""
    spool = [50.0] * 19 + [0.0] * 5
    assert not settling_on_stop(np.array(spool), np.zeros(24)).any()
    spool = [50.0] * 19 + [np.nan] + [50.0] * 19 + [0.0] * 5
    assert not settling_on_stop(np.array(spool), np.zeros(44)).any()
    assert settling_on_stop(np.array([50.0] * 20), np.zeros(20)).tolist() == [False] * 19 + [True]


def test_tracker_is_the_series_one_sample_at_a_time() -> None:
    """The live ticker's tracker and the offline series give the same flags on random
    commands and flows (holds, small and large levers, stalls, gaps)."""
    rng = np.random.default_rng(38)
    for _ in range(20):
        spool = np.repeat(rng.choice([0.0, 3.0, 10.0, -10.0, -50.0, np.nan], 100), 50)
        qp = np.repeat(rng.choice([0.0, 0.5, 5.0, np.nan], 200), 25)
        tracker = SettleTracker()
        live = [tracker.push(s, q) for s, q in zip(spool, qp, strict=True)]
        assert live == settling_on_stop(spool, qp).tolist()


def _recording() -> Recording:
    n = len(SPOOL)
    return Recording(np.arange(n) * 0.01, {"SpoolCmd": np.array(SPOOL), "QP": np.array(QP)})


def test_j_pauses_while_settling() -> None:
    """Residuals of 0.1 z off the stop and 3 z while settling: J over a window of 5 samples
    is 0.1^2 = 0.01 wherever it is judged and NaN (not judged) on the stop; judged as
    before, the same data reaches 3^2 = 9."""
    rec = _recording()
    on = np.array(SETTLING)
    e = np.where(on, 3.0, 0.1)[:, None] * np.ones((1, 4))
    left_out = J().use(JModel(4, 1.0, 2.0, stops=True)).series(e, rec)
    assert np.all(np.isnan(left_out[on]))
    judged = np.isfinite(left_out)
    assert judged[~on][4:].all()  # after the window's warm-up every sample off the stop
    np.testing.assert_allclose(left_out[judged], 0.01, rtol=1e-12)
    every = J().use(JModel(4, 1.0, 2.0)).series(e, rec)
    assert np.nanmax(every) == pytest.approx(9.0, rel=1e-12)


def test_live_window_is_the_series() -> None:
    """J's tick window over sampler rows pauses on the same samples as its series."""
    from monitor.sampling.sampler import ROW_COLUMNS

    rec = _recording()
    e = np.where(np.array(SETTLING), 3.0, 0.1)[:, None] * np.ones((1, 4))
    stat = J().use(JModel(4, 1.0, 2.0, stops=True))
    window = stat.window(ROW_COLUMNS, 4)
    live = np.array([window.step(e[i], row) for i, row in enumerate(rows_of(rec))])
    np.testing.assert_array_equal(np.isnan(live), np.isnan(stat.series(e, rec)))
    np.testing.assert_allclose(live[np.isfinite(live)], 0.01, rtol=1e-12)


@pytest.fixture(scope="module")
def normal_log():
    from monitor.resources import resource_path
    from monitor.sampling.read import read_recording

    return read_recording(resource_path("replay", "normal.log"))


def _leaving_out(model):
    m = dataclasses.replace(model, statistics=dict(model.statistics))
    J.put(m, dataclasses.replace(J.get(m), stops=True))
    return m


def test_detect_says_how_long_j_left_out(model, normal_log) -> None:
    """The shipped normal log holds the boom on its stops for 2.2 s: with a model whose J
    leaves them out, those running seconds are not judged (judged_s falls by as much) and
    the summary says so; the live ticker's J is the detector's, sample for sample."""
    from monitor.config.settings import load_config
    from monitor.detection.alarm import State
    from monitor.detection.offline import detect
    from monitor.detection.ticker import Ticker

    cfg = load_config()
    rec = normal_log
    on = settling_on_stop(rec["SpoolCmd"], rec["QP"])
    assert on.sum() > 100  # the log has such holds (else this test shows nothing)
    plain = detect(model, rec, cfg.alarm, cfg.horizon, gating=cfg.gating)
    det = detect(_leaving_out(model), rec, cfg.alarm, cfg.horizon, gating=cfg.gating)
    assert plain.summary["on_stop_not_judged_s"] is None
    ran = (det.state == State.NORMAL) | (det.state == State.FAULT)
    assert det.summary["on_stop_not_judged_s"] == pytest.approx(np.sum(ran & on) * 0.01)
    assert np.all(np.isnan(det.j[on]))
    lost = plain.summary["judged_s"] - det.summary["judged_s"]
    assert lost >= det.summary["on_stop_not_judged_s"] - 1e-9
    json.dumps(det.summary)
    ticker = Ticker(_leaving_out(model), cfg.alarm, cfg.horizon, gating=cfg.gating)
    js = np.array([ticker.tick(row).j for row in rows_of(rec)])
    np.testing.assert_array_equal(np.isnan(js), np.isnan(det.j))
    ok = np.isfinite(js)
    np.testing.assert_allclose(js[ok], det.j[ok], rtol=1e-9, atol=1e-15)


def test_model_file(model, tmp_path) -> None:
    """A file from before the rule (the shipped model) judges every sample; a model whose J
    leaves stops out says so in its header and reads back so; a bad value is named."""
    assert J.get(model).stops is False
    with np.load(craft_model(tmp_path), allow_pickle=False) as npz:
        assert STOPS_KEY not in json.loads(npz["header"].tobytes())
    path = tmp_path / "stops.model.npz"
    save_model(path, _leaving_out(model))
    back = load_model(path)
    assert J.get(back).stops is True and back.eps0 == model.eps0
    save_model(path, model)
    assert J.get(load_model(path)).stops is False
    bad = craft_model(tmp_path, set_key(STOPS_KEY, "yes"))
    with pytest.raises(ModelFileError, match=STOPS_KEY):
        load_model(bad)


def test_train_leaves_stops_out_by_default(tmp_path) -> None:
    """`monitor train`'s default (the fleet's commissioning uses the same settings), and
    ``--stops-in-j judge`` as before."""
    from monitor.cli import build_parser
    from monitor.cli.train import _config

    def stat(*extra: str) -> J:
        args = build_parser("train").parse_args(["train", "x.csv", "--out", "m.npz", *extra])
        config = _config(args, "default", ())
        fitted = J.configure(config, (), set())
        assert isinstance(fitted, J)
        return fitted

    assert StatisticSettings().j_leaves_out_stops is True
    assert stat().stops_setting is True
    assert stat("--stops-in-j", "judge").stops_setting is False


def test_threshold_not_set_by_a_stop() -> None:
    """Trained on held-out data whose only large residuals settle on a stop, J0 is the
    largest J off it (0.1^2), eps0 twice that (the max rule), and `monitor train` says how
    much it left out (41 samples, 0.41 s); judging every sample, the stop sets J0 = 3^2."""
    from monitor.model.statistic import HeldOut
    from monitor.model.threshold import ThresholdRule
    from monitor.training.statistics import said

    rec = _recording()
    e = np.where(np.array(SETTLING), 3.0, 0.1)[:, None] * np.ones((1, 4))
    held = HeldOut([e], [rec], ("PP", "PA", "PB", "QP"))
    stat = J(4, stops=True).fit(held, ThresholdRule())
    assert stat.params_.j0 == pytest.approx(0.01, rel=1e-12)
    assert stat.threshold_ == pytest.approx(0.02, rel=1e-12)
    assert "0.4 s settling on an end stop left out" in said(stat, held, ThresholdRule())
    every = J(4).fit(held, ThresholdRule())
    assert every.params_.j0 == pytest.approx(9.0, rel=1e-12)
    assert "settling" not in said(every, held, ThresholdRule())
