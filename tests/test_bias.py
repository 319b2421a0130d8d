"""The bias statistic B (monitor.model.bias) and the threshold with a stated false-alarm rate."""

from __future__ import annotations

import math

import numpy as np
import pytest
from naive import bias_statistic

from monitor.errors import InputFileError
from monitor.model.bias import (
    BATCH,
    N_BIAS_REGIMES,
    SCALE_FLOOR,
    BiasModel,
    BiasWindow,
    alarm_level,
    bias_regime,
    bias_regimes,
    bias_series,
    fit_scale,
)
from monitor.model.threshold import ThresholdRule


def _data(seed: int, n: int = 700, n_out: int = 3):
    rng = np.random.default_rng(seed)
    e = rng.normal(0.0, 1.0, (n, n_out)) * rng.uniform(0.1, 3.0, n_out)
    e[rng.random(n) < 0.05, rng.integers(0, n_out)] = np.nan  # missing samples pause
    regimes = rng.integers(0, N_BIAS_REGIMES, n)
    scale = rng.uniform(0.5, 2.0, (N_BIAS_REGIMES, n_out))
    return e, regimes, scale


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_series_matches_the_definition(seed: int) -> None:
    e, regimes, scale = _data(seed)
    bias = BiasModel(60, 7, scale, 1.0)
    got = bias_series(e, regimes, bias)
    want = bias_statistic(e, regimes, scale, 60, 7)
    assert np.array_equal(np.isnan(got), np.isnan(want))
    ok = np.isfinite(want)
    assert ok.sum() > 500
    np.testing.assert_allclose(got[ok], want[ok], rtol=1e-9)


def test_live_window_gives_the_series_numbers() -> None:
    """The ticker's one-sample pushes and the offline series run the same kernel."""
    e, regimes, scale = _data(4, n=3000)
    bias = BiasModel(200, 10, scale, 1.0)
    live = BiasWindow(bias)
    pushed = np.array([live.push(e[i], int(regimes[i])) for i in range(len(e))])
    series = bias_series(e, regimes, bias)
    assert np.array_equal(np.isnan(pushed), np.isnan(series))
    ok = np.isfinite(series)
    assert np.array_equal(pushed[ok], series[ok])


def test_regimes_split_by_direction_and_size() -> None:
    spool = np.array([0.0, 4.9, -5.0, 5.1, 60.0, 60.1, -30.0, -99.0, np.nan])
    want = [0, 0, 0, 1, 1, 2, 3, 4, 0]
    assert list(bias_regimes(spool)) == want
    assert [bias_regime(float(s)) for s in spool] == want


def test_a_steady_offset_grows_b_with_its_square_and_its_time() -> None:
    """Residuals of unit long-run scale: an offset d in one regime's output gives
    z = d sqrt(k) for its k samples in the window; B averages z^2 / n_out over the regimes
    counted, and is judged only on a full window."""
    n_out, d = 2, 0.1
    scale = np.ones((N_BIAS_REGIMES, n_out))
    e = np.zeros((700, n_out))
    e[:, 0] = d  # offset d on output 0 throughout
    regimes = np.zeros(700, dtype=np.int64)
    regimes[150:] = 1  # 150 samples of hold, then raising
    b = bias_series(e, regimes, BiasModel(400, 100, scale, 1.0))
    assert np.all(np.isnan(b[:399])) and not np.isnan(b[399])
    # At sample 399: hold 150 samples, raising 250, both offset by d on output 0.
    assert b[399] == pytest.approx((d**2 * 150 + d**2 * 250) / n_out / 2, rel=1e-12)
    # At 499: hold has 50 samples left (< 100, not counted), raising 350.
    assert b[499] == pytest.approx(d**2 * 350 / n_out, rel=1e-12)
    assert b[699] == pytest.approx(d**2 * 400 / n_out, rel=1e-12)


def test_scale_is_the_long_run_sd_of_the_mean() -> None:
    """White noise of sd s: a batch of BATCH samples has a mean of sd s / sqrt(BATCH), so the
    scale (sd of batch means x sqrt(BATCH)) is s, within its sampling error."""
    rng = np.random.default_rng(7)
    sd = np.array([0.2, 1.0])
    n = 400 * BATCH
    e = rng.normal(0.0, 1.0, (n, 2)) * sd
    regimes = np.repeat(np.arange(N_BIAS_REGIMES), n // N_BIAS_REGIMES)
    scale = fit_scale([e], [regimes])
    # 80 batches per regime: the sd estimate is within ~ 3 / sqrt(2 * 80) = 24 % at 3 sigma.
    np.testing.assert_allclose(scale, np.broadcast_to(sd, scale.shape), rtol=0.24)


def test_scale_floor_and_unseen_regimes() -> None:
    rng = np.random.default_rng(8)
    n = 20 * BATCH
    e = rng.normal(0.0, 1.0, (n, 1))
    e[: n // 2] *= 0.01  # regime 0: nearly exact
    regimes = np.where(np.arange(n) < n // 2, 0, 1)
    scale = fit_scale([e], [regimes])
    top = scale[1, 0]
    assert scale[0, 0] == pytest.approx(SCALE_FLOOR * top)
    assert np.all(scale[2:, 0] == top)  # never seen: the largest
    with pytest.raises(InputFileError, match="too little held-out"):
        fit_scale([e[: BATCH * 2]], [regimes[: BATCH * 2]])


def test_alarm_level_is_the_larger_ratio_and_j_alone_while_b_warms_up() -> None:
    bias = BiasModel(10, 1, np.ones((N_BIAS_REGIMES, 1)), 4.0)
    j = np.array([np.nan, 1.0, 1.0, 3.0])
    b = np.array([8.0, np.nan, 8.0, 8.0])
    level = alarm_level(j, 2.0, b, bias)
    assert np.isnan(level[0])
    assert list(level[1:]) == [0.5, 2.0, 2.0]
    assert list(alarm_level(j, 2.0, None, None)[1:]) == [0.5, 0.5, 1.5]


def test_evt_threshold_is_the_gumbel_return_level() -> None:
    """Block maxima drawn from a Gumbel(mu, beta): the rule's level is the analytic return
    level mu - beta ln(-ln(1 - p)), p = rate x block length, within the fit's error."""
    rng = np.random.default_rng(11)
    mu, beta, block = 5.0, 0.5, 100  # blocks of 1 s at 100 Hz
    maxima = rng.gumbel(mu, beta, 4000)
    series = rng.uniform(0.0, 1.0, (4000, block))
    series[np.arange(4000), rng.integers(0, block, 4000)] = maxima
    rule = ThresholdRule("evt", rate_per_h=0.36)  # p = 0.36 / 3600 = 1e-4 per block
    fit = rule.fit_evt(series.ravel(), block)
    want = mu - beta * math.log(-math.log(1.0 - 1e-4))
    assert fit["level"] == pytest.approx(want, rel=0.03)
    assert fit["blocks"] == 4000 and fit["loc"] == pytest.approx(mu, rel=0.02)
    j0, eps0 = rule.eps0(series.ravel(), block=block)
    assert (j0, eps0) == (pytest.approx(maxima.max()), pytest.approx(fit["level"]))


def test_evt_needs_enough_windows() -> None:
    with pytest.raises(InputFileError, match="at least 8 held-out windows of 60 s"):
        ThresholdRule("evt").fit_evt(np.ones(7 * 6000), 6000)


def _piston_wear_run(severity: float, seed: int):
    from monitor.sim.cycles import make_cycle
    from monitor.sim.faults import Fault
    from monitor.sim.machine import load_machine
    from monitor.sim.simulate import simulate

    return simulate(
        make_cycle("boom", 120.0, seed),
        load_machine(),
        faults=[Fault("piston_wear", severity, 30.0)],
        seed=seed,
    )


def test_b_finds_slight_piston_wear_that_j_misses(model) -> None:
    """Piston wear at severity 0.1 (a seal leaking 5e-13 m^3/(s Pa) from A to B): J stays
    below eps0, B crosses b0, and the alarm names the fault; live ticks agree with detect."""
    from live_support import assert_same_events, tick_recording

    from monitor.config.settings import load_config
    from monitor.detection.offline import detect
    from monitor.detection.ticker import Ticker

    assert model.bias is not None, "the shipped model carries the bias statistic"
    cfg = load_config()
    # Not seed 4242: its holds on the end stops show the leak to J as well (the trapped
    # pressures equalise, PA 180 / PB 115 bar against 200 / 0 healthy at 92 s), which the
    # shipped model, trained on such holds, now sees.
    rec = _piston_wear_run(0.1, 4246)
    det = detect(model, rec, cfg.alarm, cfg.horizon)
    s = det.summary
    assert s["max_J"] < s["threshold"]
    assert s["max_B"] > s["bias_threshold"] and s["max_level"] == pytest.approx(
        s["max_B"] / s["bias_threshold"]
    )
    assert s["alarm"] and s["first_alarm_t"] > 30.0 and s["fault"] == "piston_wear"
    _, events = tick_recording(Ticker(model, cfg.alarm, cfg.horizon), rec)
    assert_same_events(events, det)


def test_short_held_out_data_trains_without_b() -> None:
    """Less held-out data than the bias statistic needs: J alone, and the model says why."""
    from monitor.sim.cycles import make_cycle
    from monitor.sim.machine import load_machine
    from monitor.sim.simulate import simulate
    from monitor.training.settings import IsolationSettings, TrainConfig
    from monitor.training.train import train

    recs = [simulate(make_cycle("boom", 120.0, s), load_machine(), seed=s) for s in (1, 2, 3)]
    said: list[str] = []
    m = train(
        recs[:2], TrainConfig(isolation=IsolationSettings("none")), said.append, held_out=recs[2:]
    )
    assert m.bias is None
    assert m.training["bias"].startswith("off: ")
    assert any("bias statistic off" in line for line in said)
