"""The rig's bias statistic B (``monitor.evaluation.uci_bias``), worked by hand: phase means,
scales from healthy cycles, b0 by the threshold rule, and what alarms."""

from __future__ import annotations

import numpy as np
import pytest

from monitor.evaluation.uci_bias import CycleRule, cycle_b, phase_means, phase_scale
from monitor.model.threshold import ThresholdRule


def test_phase_means_by_hand() -> None:
    # One cycle of 7 s, two outputs, phases of 3 s: seconds 0-2, 3-5; second 6 is left out.
    e = np.array(
        [
            [
                [np.nan, 1.0],
                [2.0, 1.0],
                [4.0, 1.0],
                [1.0, -3.0],
                [1.0, np.nan],
                [1.0, 0.0],
                [9.0, 9.0],
            ]
        ]
    )
    got = phase_means(e, 3)
    np.testing.assert_allclose(got, [[[3.0, 1.0], [1.0, -1.5]]])
    assert np.isnan(phase_means(np.full((1, 3, 1), np.nan), 3)[0, 0, 0])  # nothing predicted


def _cycles(offsets: list[float]) -> np.ndarray:
    """Cycles of 20 s, one output, two 10 s phases: the second phase carries the offset."""
    e = np.zeros((len(offsets), 20, 1))
    for i, off in enumerate(offsets):
        e[i, :10, 0] = 0.1 * (-1) ** i  # phase 1: +-0.1, the healthy scatter
        e[i, 10:, 0] = off
    return e


def test_scales_b0_and_alarms_by_hand() -> None:
    healthy = [0.2, -0.5, 0.3, 0.4]  # held-out: phase 2's largest |mean| is 0.5
    means = phase_means(_cycles([*healthy, 0.9, 1.1, -1.2]), 10)
    idx = np.arange(4)
    scale = phase_scale(means[idx])
    np.testing.assert_allclose(scale, [[0.1], [0.5]])
    # B of the new cycles: |0.9| / 0.5 = 1.8, 2.2, 2.4; of the held-out ones at most 1.
    np.testing.assert_allclose(cycle_b(means, scale), [1.0, 1.0, 1.0, 1.0, 1.8, 2.2, 2.4])
    jmax = np.array([1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 5.0])
    rule = CycleRule.fit(jmax, means, idx, ThresholdRule("max", factor=2.0))
    assert rule.eps0 == pytest.approx(2.0) and rule.b0 == pytest.approx(2.0)
    # 0.9 stays below b0 = 2; 1.1 alarms by B alone; the last by J and B.
    assert list(rule.alarms(jmax, means)) == [False] * 5 + [True, True]
    # Judged at the end of the phase that crosses: second 19 of the cycle.
    np.testing.assert_array_equal(rule.first_b_alarm_s(means, 10)[4:], [np.nan, 19.0, 19.0])
    j_alone = CycleRule.fit(jmax, None, idx, ThresholdRule("max", factor=2.0))
    assert list(j_alone.alarms(jmax, None)) == [False] * 6 + [True]


def test_an_entry_never_off_zero_is_never_judged() -> None:
    """A phase the model predicts exactly on every held-out cycle has no scale: skipped, not
    a division by zero that alarms on everything."""
    e = np.zeros((3, 20, 1))
    e[:, 10:, 0] = [[0.1], [-0.2], [0.3]]
    means = phase_means(e, 10)
    scale = phase_scale(means[:2])
    assert np.isnan(scale[0, 0]) and scale[1, 0] == pytest.approx(0.2)
    np.testing.assert_allclose(cycle_b(means, scale), [0.5, 1.0, 1.5])
