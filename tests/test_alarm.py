"""Alarm state machine, isolation and threshold rules, on hand-made sequences."""

from __future__ import annotations

import numpy as np
import pytest

from monitor.detection.alarm import AlarmConfig, AlarmMachine, Isolator, State, classify, regime_of
from monitor.errors import ConfigError
from monitor.model.threshold import ThresholdRule

CFG = AlarmConfig(
    raise_samples=3, clear_samples=4, clear_ratio=0.5, sensor_recover_samples=2, min_engine_rpm=500
)


def run(js, ok=None, rpm=None):
    m = AlarmMachine(CFG, eps0=1.0)
    ok = ok or [True] * len(js)
    rpm = rpm or [2200.0] * len(js)
    return [m.step(j, o, r).name[0] for j, o, r in zip(js, ok, rpm, strict=True)]


def test_fault_needs_raise_samples_in_a_row():
    assert "".join(run([2, 2, 0, 2, 2, 0])) == "NNNNNN"
    assert "".join(run([2, 2, 2, 2])) == "NNFF"


def test_fault_clears_only_below_the_hysteresis_level_for_clear_samples():
    # 0.8 is below eps0 but above 0.5 * eps0: the fault holds.
    seq = [2, 2, 2] + [0.8] * 6 + [0.4] * 3 + [0.8] + [0.4] * 4
    assert "".join(run(seq)) == "NNF" + "F" * 6 + "FFF" + "F" + "FFFN"


def test_nan_j_neither_raises_nor_clears():
    assert "".join(run([2, np.nan, 2, 2])) == "NNNF"


def test_sensor_fault_and_recovery():
    ok = [True, False, False, True, True, True]
    assert "".join(run([0] * 6, ok=ok)) == "NSSSNN"


def test_engine_off_is_inactive_not_a_fault():
    rpm = [2200, 0, float("nan"), 100, 2200, 2200]
    # Sensor data missing while the engine is off is still just "inactive".
    ok = [True, False, True, True, True, True]
    assert "".join(run([5] * 6, ok=ok, rpm=rpm)) == "NIIINN"


def test_bad_alarm_config_is_refused():
    with pytest.raises(ConfigError):
        AlarmConfig(raise_samples=0)
    with pytest.raises(ConfigError):
        AlarmConfig(clear_ratio=1.5)


def test_regimes():
    assert [regime_of(v) for v in (0.0, 5.0, 5.1, -5.1, 80.0)] == [0, 0, 1, 2, 1]


def test_isolation_by_direction_not_length():
    labels = ("a", "b")
    centroids = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]])
    assert classify(np.array([10.0, 1.0, 0.0, 0.0]), labels, centroids, 0.5) == "a"
    assert classify(np.array([0.1, 2.0, 0.0, 0.0]), labels, centroids, 0.5) == "b"
    # Equally far from both (cosine 0.707 each, first wins) and opposite to both.
    assert classify(np.array([-1.0, -1.0, 0.0, 0.0]), labels, centroids, 0.5) == "unknown"
    # Unseen regimes (NaN) are left out of the comparison.
    assert classify(np.array([np.nan, 3.0, np.nan, 0.0]), labels, centroids, 0.5) == "b"


def test_isolator_means_per_regime():
    iso = Isolator(("x",), np.ones((1, 6)), n_outputs=2)
    iso.add(np.array([1.0, 2.0]), 1)
    iso.add(np.array([3.0, 4.0]), 1)
    iso.add(np.array([np.nan, 4.0]), 2)  # incomplete rows are not counted
    sig = iso.signature()
    assert np.isnan(sig[0]) and np.isnan(sig[4])
    np.testing.assert_allclose(sig[2:4], [2.0, 3.0])


def test_alarm_seeds_isolation_with_the_window_that_raised_it():
    iso = Isolator(("up", "down"), np.array([[0, 0, 1, 0, 0, 0], [0, 0, -1, 0, 0, 0]], float), 2)
    m = AlarmMachine(CFG, eps0=1.0, isolator=iso, window_n=5)
    for _ in range(2):
        m.step(2.0, True, 2200.0, np.array([-1.0, 0.0]), 1)
    assert m.step(2.0, True, 2200.0, np.array([-1.0, 0.0]), 1) is State.FAULT
    assert m.fault == "down"


def test_threshold_rules_by_hand():
    j = np.array([np.nan, 0.1, 0.2, 0.3, 0.4])
    assert ThresholdRule("max").eps0(j) == pytest.approx((0.4, 0.8))
    assert ThresholdRule("mean").eps0(j) == pytest.approx((0.25, 0.5))
    assert ThresholdRule("quantile", quantile=0.5).eps0(j)[0] == pytest.approx(0.25)
    assert ThresholdRule("max", factor=3.0).eps0(j)[1] == pytest.approx(1.2)
    with pytest.raises(ConfigError):
        ThresholdRule("median")


def test_isolator_add_many_is_add_row_by_row_to_the_bit() -> None:
    """A raise seeds the isolation with the window's N residuals at once; the sums must be
    those of adding them one by one (NaN rows skipped), so decisions do not change."""
    rng = np.random.default_rng(3)
    e = rng.normal(size=(1000, 4)) * rng.choice([1e-3, 1.0, 1e3], size=(1000, 1))
    e[rng.random(1000) < 0.1, rng.integers(0, 4)] = np.nan  # stale rows are skipped
    regimes = rng.integers(0, 3, size=1000)
    one = Isolator(("a", "b"), np.eye(2, 12), 4)
    for row, r in zip(e, regimes, strict=True):
        one.add(row, int(r))
    many = Isolator(("a", "b"), np.eye(2, 12), 4)
    many.add_many(e, regimes)
    np.testing.assert_array_equal(many.sums, one.sums)
    np.testing.assert_array_equal(many.counts, one.counts)
    assert many.counts.sum() == np.isfinite(e).all(axis=1).sum()


def episode_run(js, rpm, gap_samples=5):
    """States and the samples that raised a new episode, with ``episode_gap_samples``."""
    cfg = AlarmConfig(
        raise_samples=3,
        clear_samples=4,
        clear_ratio=0.5,
        sensor_recover_samples=2,
        min_engine_rpm=500,
        episode_gap_samples=gap_samples,
    )
    m = AlarmMachine(cfg, eps0=1.0)
    states, raised = [], []
    for k, (j, r) in enumerate(zip(js, rpm, strict=True)):
        states.append(m.step(j, True, r).name[0])
        if m.raised:
            raised.append(k)
    return "".join(states), raised


def test_a_short_gap_inside_a_fault_is_one_episode():
    # Fault raised at sample 2, engine off for 3 samples (<= 5), J still high after it:
    # straight back to fault, no new debounce and no new raise.
    js = [2, 2, 2, 2, 9, 9, 9, 2, 2]
    rpm = [2200] * 4 + [0] * 3 + [2200] * 2
    states, raised = episode_run(js, rpm)
    assert states == "NNFFIIIFF" and raised == [2]


def test_a_long_gap_ends_the_episode():
    # The same with the engine off for 6 samples (> 5): the next fault is a new episode,
    # raised after the full debounce.
    js = [2, 2, 2, 2] + [9] * 6 + [2, 2, 2, 2]
    rpm = [2200] * 4 + [0] * 6 + [2200] * 4
    states, raised = episode_run(js, rpm)
    assert states == "NNFF" + "I" * 6 + "NNFF" and raised == [2, 12]


def test_the_clear_rule_still_ends_an_episode_after_a_gap():
    js = [2, 2, 2, 9, 0.1, 0.1, 0.1, 0.1, 2, 2, 2]
    rpm = [2200, 2200, 2200, 0] + [2200] * 7
    states, raised = episode_run(js, rpm)
    assert states == "NNFI" + "FFFN" + "NNF" and raised == [2, 10]
