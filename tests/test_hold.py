"""The hold statistic H (monitor.model.hold, issue 17): PA's and PB's mean residual over the
settled hold samples of a window, tested against the twin in tests/naive.py written from the
definition alone."""

from __future__ import annotations

import copy
import dataclasses
import json

import numpy as np
import pytest
from model_support import craft_model, set_key
from naive import hold_statistic

from monitor.errors import ConfigError, InputFileError, ModelFileError
from monitor.model.bias import N_BIAS_REGIMES, BiasModel, alarm_level
from monitor.model.hold import (
    HoldModel,
    HoldWindow,
    fit_hold_scale,
    hold_flags,
    hold_series,
)
from monitor.model.modelfile import load_model, save_model


def _data(seed: int, n: int = 900, n_out: int = 4):
    """Residuals with NaN rows and commands in and out of hold, holds of varied length."""
    rng = np.random.default_rng(seed)
    e = rng.normal(0.0, 1.0, (n, n_out)) * rng.uniform(0.1, 3.0, n_out)
    e[:, 1:3] += rng.normal(0.0, 0.5, 2)  # offsets on PA and PB so that the means are not ~0
    e[rng.random(n) < 0.03, rng.integers(0, n_out)] = np.nan  # missing samples pause
    levels = [-50.0, -5.0, -4.9, 0.0, 0.0, 0.0, 3.0, 5.0, 5.01, 60.0, np.nan]
    spool = np.repeat(rng.choice(levels, n), rng.integers(1, 12, n))[:n]  # runs of a level
    scale = rng.uniform(0.5, 2.0, 2)
    return e, spool, scale


@pytest.mark.parametrize("seed", [1, 2, 3, 4])
def test_series_matches_the_definition(seed: int) -> None:
    e, spool, scale = _data(seed)
    hold = HoldModel(60, 5, 3, (1, 2), scale, 1.0)
    got = hold_series(e, hold_flags(spool), hold)
    want = hold_statistic(e, spool, (1, 2), scale, 60, 3, 5)
    assert np.array_equal(np.isnan(got), np.isnan(want))
    ok = np.isfinite(want)
    assert ok.sum() > 400
    np.testing.assert_allclose(got[ok], want[ok], rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("settle", [0, 1, 8])
def test_series_matches_the_definition_for_other_settings(settle: int) -> None:
    """One watched output (3), no settling or a long one, a tight count."""
    e, spool, scale = _data(7, n=1200)
    hold = HoldModel(40, 12, settle, (3,), scale[:1], 1.0)
    got = hold_series(e, hold_flags(spool), hold)
    want = hold_statistic(e, spool, (3,), scale[:1], 40, settle, 12)
    assert np.array_equal(np.isnan(got), np.isnan(want))
    ok = np.isfinite(want)
    assert ok.sum() > 100
    np.testing.assert_allclose(got[ok], want[ok], rtol=1e-9, atol=1e-12)


def test_live_window_gives_the_series_numbers() -> None:
    """The ticker's one-sample pushes and the offline series give the very same numbers,
    across the kernel's exact re-summation (every 1000 pushes for this window)."""
    e, spool, scale = _data(6, n=3500)
    hold = HoldModel(90, 10, 4, (1, 2), scale, 1.0)
    flags = hold_flags(spool)
    live = HoldWindow(hold)
    pushed = np.array([live.push(e[i], float(spool[i]), np.nan) for i in range(len(e))])
    series = hold_series(e, flags, hold)
    assert np.array_equal(np.isnan(pushed), np.isnan(series))
    ok = np.isfinite(series)
    assert ok.sum() > 2000
    assert np.array_equal(pushed[ok], series[ok])


def test_hold_is_within_5_percent() -> None:
    spool = np.array([0.0, 5.0, -5.0, 5.0001, -5.0001, 4.9, -100.0, np.nan])
    want = [1, 1, 1, 0, 0, 1, 0, 0]
    got = hold_flags(spool)
    assert got.dtype == np.int64
    assert list(got) == want


# Worked on paper: window 4, settle 1, min_count 2, outputs (0, 1), scale (1, 2).
# The residual is missing (NaN in output 2) at sample 5.
HAND_SPOOL = [0.0, 0.0, 0.0, 50.0, 0.0, 0.0, 0.0, 0.0, 2.0, -3.0, 20.0, 0.0]
HAND_E0 = [9.0, 1.0, 3.0, 7.0, 8.0, 0.0, 2.0, 4.0, -1.0, 6.0, 5.0, 1.0]
HAND_E1 = [9.0, -4.0, -2.0, 7.0, 8.0, 0.0, 0.0, -6.0, 2.0, -2.0, 5.0, 3.0]
# Hold ages: 1, 2, 3, 0, 1, (NaN: none, the age resets), 1, 2, 3, 4, 0, 1.
# Counted (age > 1): samples 1, 2, 7, 8, 9.


def _hand_expected() -> list[float]:
    """The hand-worked values, sample by sample (window of the last 4 valid samples).
    3: window {0,1,2,3}, counted {1,2}: PA |1 + 3| / 2 / 1 = 2, PB |-4 - 2| / 2 / 2 = 1.5: 2.
    4: window {1,2,3,4}, counted {1,2} (4 has age 1): 2 again.
    5: NaN residual.
    6: window {2,3,4,6}, counted {2}: too few.
    7: window {3,4,6,7}, counted {7}: too few.
    8: window {4,6,7,8}, counted {7,8}: PA |4 - 1| / 2 = 1.5, PB |-6 + 2| / 2 / 2 = 1: 1.5.
    9: window {6,7,8,9}, counted {7,8,9}: PA |4 - 1 + 6| / 3 = 3, PB |-6 + 2 - 2| / 3 / 2 = 1: 3.
    10: window {7,8,9,10}, counted {7,8,9}: 3 again (10 is a move).
    11: window {8,9,10,11}, counted {8,9}: PA |-1 + 6| / 2 = 2.5, PB 0: 2.5."""
    nan = np.nan
    return [nan, nan, nan, 2.0, 2.0, nan, nan, nan, 1.5, 3.0, 3.0, 2.5]


def _hand():
    e = np.zeros((len(HAND_E0), 3))
    e[:, 0] = HAND_E0
    e[:, 1] = HAND_E1
    e[5, 2] = np.nan
    return e, np.array(HAND_SPOOL)


def test_hand_worked_sequence() -> None:
    e, spool = _hand()
    want = _hand_expected()
    hold = HoldModel(4, 2, 1, (0, 1), np.array([1.0, 2.0]), 1.0)
    got = hold_series(e, hold_flags(spool), hold)
    np.testing.assert_array_equal(got, np.array(want))
    np.testing.assert_array_equal(hold_statistic(e, spool, (0, 1), [1.0, 2.0], 4, 1, 2), want)
    live = HoldWindow(hold)
    pushed = [live.push(e[i], float(spool[i]), np.nan) for i in range(len(e))]
    np.testing.assert_array_equal(np.array(pushed), np.array(want))


def _cycles(n: int = 3000):
    """Cycles of 5 s at 100 Hz: 1 s raising at 60 %, 3 s hold, 1 s lowering at -60 %."""
    one = np.concatenate([np.full(100, 60.0), np.zeros(300), np.full(100, -60.0)])
    return np.resize(one, n)


def test_a_steady_offset_in_settled_holds_raises_h_in_proportion() -> None:
    spool = _cycles()
    hold = HoldModel(1000, 100, 200, (1, 2), np.array([0.5, 2.0]), 1.0)
    f = hold_flags(spool)
    age = np.zeros(len(spool), dtype=int)
    for i in range(len(spool)):
        age[i] = (age[i - 1] + 1 if i else 1) if f[i] else 0
    settled = age > 200
    for offset in (0.1, 0.2, 0.4):
        e = np.zeros((len(spool), 4))
        e[settled, 1] = offset  # PA reads `offset` off in settled holds, exact elsewhere
        e[f.astype(bool) & ~settled, 1] = -3.0  # hold entry: not counted
        h = hold_series(e, f, hold)
        assert np.all(np.isnan(h[:999])) and np.all(np.isfinite(h[999:]))
        np.testing.assert_allclose(h[999:], offset / 0.5, rtol=1e-12)
    e = np.zeros((len(spool), 4))
    e[settled, 2] = -0.4  # PB: |-0.4| / 2.0
    np.testing.assert_allclose(hold_series(e, f, hold)[999:], 0.2, rtol=1e-12)


def test_residuals_elsewhere_leave_h_unchanged() -> None:
    """Other outputs' residuals, or PA's and PB's in moves and unsettled holds, do not
    move H."""
    rng = np.random.default_rng(9)
    spool = _cycles()
    f = hold_flags(spool)
    e = rng.normal(0.0, 0.3, (len(spool), 4))
    hold = HoldModel(1000, 100, 200, (1, 2), np.array([1.0, 1.5]), 1.0)
    base = hold_series(e, f, hold)
    assert np.isfinite(base[999:]).all()
    other = e.copy()
    other[:, [0, 3]] += 5.0  # PP and QP far off
    np.testing.assert_array_equal(hold_series(other, f, hold), base)
    moving = e.copy()
    moving[f == 0, 1:3] += 5.0  # PA and PB far off, but only in moves
    np.testing.assert_array_equal(hold_series(moving, f, hold), base)


@pytest.mark.parametrize(
    "args",
    [
        (1, 1, 0, (1,), [1.0]),  # window
        (10, 0, 0, (1,), [1.0]),  # min_count
        (10, 11, 0, (1,), [1.0]),  # min_count beyond the window: H never defined
        (10, 2, -1, (1,), [1.0]),  # settle
        (10, 2, 0, (), []),  # no output
        (10, 2, 0, (-1,), [1.0]),  # output
        (10, 2, 0, (1, 2), [1.0]),  # scale: one per output
        (10, 2, 0, (1, 2), [1.0, 0.0]),  # scale: positive
        (10, 2, 0, (1, 2), [1.0, np.nan]),
    ],
)
def test_bad_settings_are_a_config_error(args) -> None:
    window, min_count, settle, outputs, scale = args
    with pytest.raises(ConfigError):
        HoldModel(window, min_count, settle, outputs, np.array(scale), 1.0)


def test_to_dict_round_trip() -> None:
    hold = HoldModel(6000, 300, 200, (1, 2), np.array([0.25, 0.75]), 2.0)
    d = json.loads(json.dumps(hold.to_dict()))  # as the model file's JSON header holds it
    back = HoldModel.from_dict(d)
    assert (back.window_n, back.min_count, back.settle_n, back.outputs, back.h0) == (
        6000,
        300,
        200,
        (1, 2),
        2.0,
    )
    assert np.array_equal(back.scale, hold.scale)
    assert back.to_dict() == hold.to_dict()


def test_fit_scale_by_hand() -> None:
    """Window 3, settle 0, min_count 2, outputs (0, 1).
    Recording A, spool (0, 0, 50, 0), e0 (1, 3, 99, -2), e1 (0, 1, 99, 1):
      at 2 {0,1,2}: counted {0,1}: e0 mean 2, e1 mean 0.5;
      at 3 {1,2,3}: counted {1,3}: e0 |3 - 2| / 2 = 0.5, e1 1.
    Recording B, spool (0, 0, 0), e0 (0, 0, 0.3), e1 (-3, -3, 0):
      at 2: e0 0.1, e1 2.
    Per output the largest: e0 2, e1 2."""
    a = np.array([[1.0, 0.0], [3.0, 1.0], [99.0, 99.0], [-2.0, 1.0]])
    b = np.array([[0.0, -3.0], [0.0, -3.0], [0.3, 0.0]])
    fa = hold_flags(np.array([0.0, 0.0, 50.0, 0.0]))
    fb = hold_flags(np.zeros(3))
    np.testing.assert_allclose(fit_hold_scale([a, b], [fa, fb], 3, 2, 0, (0, 1)), [2.0, 2.0])


def test_fit_scale_is_the_per_output_max_of_the_definition() -> None:
    recs = [_data(s, n=900) for s in (11, 12)]
    es = [r[0] for r in recs]
    spools = [r[1] for r in recs]
    got = fit_hold_scale(es, [hold_flags(s) for s in spools], 60, 5, 3, (1, 2))
    want = [
        max(
            np.nanmax(hold_statistic(e, s, (o,), [1.0], 60, 3, 5))
            for e, s in zip(es, spools, strict=True)
        )
        for o in (1, 2)
    ]
    np.testing.assert_allclose(got, want, rtol=1e-9)


def test_fit_scale_needs_settled_holds_in_a_full_window() -> None:
    e = np.ones((20, 2))
    with pytest.raises(InputFileError, match="hold"):  # holds never settle for 5 samples
        fit_hold_scale([e], [hold_flags(np.resize([0.0, 0.0, 0.0, 50.0], 20))], 6, 2, 5, (0, 1))
    with pytest.raises(InputFileError):  # never a full window
        fit_hold_scale([e[:5]], [hold_flags(np.zeros(5))], 6, 2, 0, (0, 1))
    np.testing.assert_array_equal(
        fit_hold_scale([e[:6]], [hold_flags(np.zeros(6))], 6, 2, 0, (0, 1)), [1.0, 1.0]
    )


J = np.array([np.nan, 1.0, 1.0, 1.0, 3.0, 1.0])  # / eps0 2: nan, 0.5, 0.5, 0.5, 1.5, 0.5
B = np.array([8.0, np.nan, 8.0, 8.0, 8.0, np.nan])  # / b0 4:  2,  nan, 2,   2,   2,   nan
LEV = np.array([9.0, 9.0, np.nan, 3.0, 12.0, np.nan])  # / l0 3: 3, 3,  nan, 1,   4,   nan
HST = np.array([50.0, np.nan, 25.0, 5.0, 2.0, np.nan])  # / h0 5: 10, nan, 5,   1,   0.4, nan


def test_alarm_level_with_hold_is_the_largest_finite_ratio() -> None:
    bias = BiasModel(10, 1, np.ones((N_BIAS_REGIMES, 1)), 4.0)
    level = alarm_level(J, 2.0, B, bias, lever=(LEV, 3.0), hold=(HST, 5.0))
    assert np.isnan(level[0])  # J missing: NaN whatever the others say
    assert list(level[1:]) == [3.0, 5.0, 2.0, 4.0, 0.5]
    only_h = alarm_level(J, 2.0, None, None, hold=(HST, 5.0))
    assert list(only_h[1:]) == [0.5, 5.0, 1.0, 1.5, 0.5]
    # h0 NaN: H computed but never alarms.
    assert list(alarm_level(J, 2.0, None, None, hold=(HST, np.nan))[1:]) == list(J[1:] / 2.0)


def test_model_file_keeps_h(tmp_path, model) -> None:
    hold = HoldModel(6000, 300, 200, (1, 2), np.array([0.3, 0.7]), 2.0)
    with_h = dataclasses.replace(model, hold=hold)
    path = tmp_path / "m.npz"
    save_model(path, with_h)
    back = load_model(path)
    assert back.hold is not None
    assert back.hold.to_dict() == hold.to_dict()
    assert back.header() == with_h.header()
    assert back.header()["hold"] == hold.to_dict()
    save_model(path, dataclasses.replace(model, hold=None))
    again = load_model(path)
    assert again.hold is None and "hold" not in again.header()


GOOD = {
    "window_n": 6000,
    "min_count": 300,
    "settle_n": 200,
    "outputs": [1, 2],
    "scale": [0.3, 0.7],
    "h0": 2.0,
}


def test_crafted_good_hold_header_loads(tmp_path) -> None:
    m = load_model(craft_model(tmp_path, set_key("hold", GOOD)))
    assert m.hold is not None and m.hold.to_dict() == GOOD


@pytest.mark.parametrize(
    "change",
    [
        {"window_n": 0},
        {"h0": -1.0},
        {"scale": [0.3]},
        {"outputs": [1, 4]},
        {"min_count": 0},
        {"settle_n": -1},
        {"settle_n": 2.5},
    ],
)
def test_a_malformed_hold_header_is_a_model_file_error_naming_hold(tmp_path, change) -> None:
    with pytest.raises(ModelFileError, match="hold") as exc:
        load_model(craft_model(tmp_path, set_key("hold", {**GOOD, **change})))
    assert "crafted.npz" in str(exc.value) and "\n" not in str(exc.value)


def test_a_hold_header_that_is_no_object_is_a_model_file_error(tmp_path) -> None:
    with pytest.raises(ModelFileError, match="hold"):
        load_model(craft_model(tmp_path, set_key("hold", [1, 2])))


def test_detect_summary_has_max_h_and_hold_threshold(model) -> None:
    """Offline detection: H is the definition over the detection's residuals and SpoolCmd;
    the summary's max_H its largest finite value, hold_threshold h0 (both null without)."""
    from monitor.config.settings import load_config
    from monitor.detection.offline import detect
    from monitor.sim.cycles import make_cycle
    from monitor.sim.machine import load_machine
    from monitor.sim.simulate import simulate

    cfg = load_config()
    rec = simulate(make_cycle("boom", 30.0, 5), load_machine(), seed=5)
    s = detect(dataclasses.replace(model, hold=None), rec, cfg.alarm, cfg.horizon).summary
    assert s["max_H"] is None and s["hold_threshold"] is None
    hold = HoldModel(200, 1, 20, (1, 2), np.array([1.0, 2.0]), 2.0)  # 2 s window, 0.2 s settle
    det = detect(dataclasses.replace(model, hold=hold), rec, cfg.alarm, cfg.horizon)
    want = hold_statistic(det.residual, rec.columns["SpoolCmd"], (1, 2), [1.0, 2.0], 200, 20, 1)
    assert np.isfinite(want).sum() > 100
    s = det.summary
    assert s["hold_threshold"] == 2.0
    assert s["max_H"] == pytest.approx(np.nanmax(want), rel=1e-9)
    assert json.loads(json.dumps(s))["max_H"] == s["max_H"]  # the --json summary


def test_live_ticker_gives_the_offline_h_and_events(model) -> None:
    """The live ticker's H equals the offline series sample by sample, and with H in the
    level both paths give the same events."""
    from live_support import assert_same_events, rows_of

    from monitor.config.settings import load_config
    from monitor.detection.offline import detect
    from monitor.detection.ticker import Ticker, event
    from monitor.sim.cycles import make_cycle
    from monitor.sim.machine import load_machine
    from monitor.sim.simulate import simulate

    cfg = load_config()
    rec = simulate(make_cycle("boom", 40.0, 6), load_machine(), seed=6)
    # Tiny scales: H rules the level, and the alarm is raised by H.
    hold = HoldModel(300, 1, 20, (1, 2), np.array([1e-4, 1e-4]), 2.0)
    m = dataclasses.replace(model, hold=hold)
    det = detect(m, rec, cfg.alarm, cfg.horizon)
    assert det.summary["alarm"]
    ticker = Ticker(m, cfg.alarm, cfg.horizon)
    hs, events = np.empty(len(rec)), []
    for i, row in enumerate(rows_of(rec)):
        tick = ticker.tick(row)
        hs[i] = ticker.value("H")
        if tick.changed:
            events.append(event(tick, ticker.fault, ticker.eps0, rec.meta.get("start_time_s")))
    assert np.array_equal(np.isnan(hs), np.isnan(det.series["H"]))
    ok = np.isfinite(det.series["H"])
    assert ok.sum() > 1000
    np.testing.assert_allclose(hs[ok], det.series["H"][ok], rtol=1e-9)
    assert_same_events(events, det)


def _boom_runs(seeds):
    from monitor.sim.cycles import make_cycle
    from monitor.sim.machine import load_machine
    from monitor.sim.simulate import simulate

    return [simulate(make_cycle("boom", 120.0, s), load_machine(), seed=s) for s in seeds]


@pytest.fixture(scope="module")
def boom_runs():
    """Eight normal boom runs of 120 s: 2 to fit, 6 held out (enough for B, L and H)."""
    return _boom_runs(range(1, 9))


def _train(fit, held_out, hold: bool = True):
    from monitor.training.settings import (
        DGRNNSettings,
        IsolationSettings,
        StatisticSettings,
        TrainConfig,
    )
    from monitor.training.train import train

    said: list[str] = []
    cfg = TrainConfig(
        DGRNNSettings(max_patterns=400),
        # H's own mechanics: B (which H needs) kept whatever minutes of data support it
        statistics=StatisticSettings(hold=hold, support_check=False),
        isolation=IsolationSettings("none"),
    )
    return train(fit, cfg, said.append, held_out=held_out), said


def test_h_is_off_unless_asked_for(boom_runs) -> None:
    """H is opt-in (``--hold on``): by default the model has B and no H, and says why."""
    m, said = _train(boom_runs[:2], boom_runs[2:], hold=False)
    assert m.bias is not None
    assert m.hold is None
    assert m.training["hold"] == "off (not asked for: --hold on)"
    assert not any("hold statistic H" in line for line in said)


def test_training_puts_h0_at_twice_the_held_out_max(boom_runs) -> None:
    """The scales are the held-out maxima, so the held-out H peaks at exactly 1, and the max
    rule with factor 2 puts h0 at 2."""
    m, said = _train(boom_runs[:2], boom_runs[2:])
    assert m.bias is not None and m.hold is not None
    outs = list(m.dgrnn.spec.outputs)
    assert m.hold.outputs == (outs.index("PA"), outs.index("PB"))
    assert (m.hold.window_n, m.hold.min_count, m.hold.settle_n) == (6000, 300, 200)
    assert m.hold.h0 == pytest.approx(2.0, rel=1e-12)
    assert np.all(m.hold.scale > 0) and m.hold.scale.shape == (2,)
    assert m.training["hold"].startswith("on")  # ", thinly supported": --support-check off
    assert any("hold statistic H" in line for line in said)


def test_held_out_data_without_long_holds_trains_without_h(boom_runs) -> None:
    held = [copy.deepcopy(r) for r in boom_runs[2:]]
    for r in held:  # the lever never rests: a 10 % command wherever it was in hold
        s = r.columns["SpoolCmd"]
        r.columns["SpoolCmd"] = np.where(np.abs(s) <= 5.0, 10.0, s)
    m, _ = _train(boom_runs[:2], held)
    assert m.bias is not None
    assert m.hold is None
    assert m.training["hold"].startswith("off: ")


def test_short_held_out_data_trains_without_h(boom_runs) -> None:
    """Too little held-out data for the bias statistic (one run of 120 s): H is off too."""
    m, said = _train(boom_runs[:2], boom_runs[2:3])
    assert m.bias is None
    assert m.hold is None
    assert m.training["hold"].startswith("off")
    # --hold on asked for it: the progress says it is off and that it needs B, not only
    # the model file's note (a stick section trained with --hold on said nothing of H).
    off = [line for line in said if "hold statistic H off" in line]
    assert len(off) == 1 and "bias statistic" in off[0]
