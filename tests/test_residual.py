"""Residual (eq. 8) and windowed J (eq. 9): hand examples, incremental == batch == naive."""

from __future__ import annotations

import math

import naive
import numpy as np
import pytest

from monitor.errors import ConfigError, InputFileError
from monitor.model.residual import WindowJ, residuals, squared_residual, window_j


def test_residual_sign_is_prediction_minus_measurement():
    np.testing.assert_array_equal(residuals([3.0, 1.0], [1.0, 1.5]), [2.0, -0.5])
    with pytest.raises(InputFileError):
        residuals([1.0, 2.0], [1.0])


def test_j_hand_example_window_holds_n_plus_1():
    e = np.array([1.0, 2.0, 3.0, 4.0])
    J = window_j(e, N=2)  # N + 1 = 3 samples per window
    assert np.isnan(J[:2]).all()
    assert J[2] == pytest.approx((1 + 4 + 9) / 3)
    assert J[3] == pytest.approx((4 + 9 + 16) / 3)
    w = WindowJ(2)
    out = [w.update(float(v)) for v in e]
    np.testing.assert_allclose(out, J, equal_nan=True)
    assert w.ready and w.value == pytest.approx(29 / 3)


def test_j_n0_is_the_squared_residual():
    e = np.array([0.5, -2.0])
    np.testing.assert_allclose(window_j(e, 0), [0.25, 4.0])


def test_multi_output_averages_squares_over_outputs():
    e = np.array([[1.0, 3.0], [2.0, 0.0], [np.nan, 1.0]])
    np.testing.assert_allclose(squared_residual(e), [5.0, 2.0, np.nan])
    J = window_j(e, 1)
    np.testing.assert_allclose(J, [np.nan, 3.5, np.nan])
    w = WindowJ(1)
    assert math.isnan(w.update(e[0]))
    assert w.update(e[1]) == pytest.approx(3.5)
    assert math.isnan(w.update(e[2])) and w.value == pytest.approx(3.5)


def test_nan_pauses_the_window():
    e = np.array([1.0, 2.0, np.nan, np.nan, 3.0, 4.0])
    J = window_j(e, 1)
    # valid samples 1, 2, 3, 4 -> windows {1,2}, {2,3}, {3,4}; NaN where data is missing
    np.testing.assert_allclose(J, [np.nan, 2.5, np.nan, np.nan, 6.5, 12.5])


def test_incremental_equals_batch_equals_naive_over_1e5_ticks():
    rng = np.random.default_rng(0)
    n = 100_000
    e = rng.standard_normal((n, 3)) * np.exp(rng.standard_normal((n, 1)))
    e[rng.random(n) < 0.01, rng.integers(0, 3)] = np.nan  # missing samples
    e[50_000:50_300] = np.nan  # a gap
    N = 100
    batch = window_j(e, N)
    ref = naive.window_j(squared_residual(e), N)
    w = WindowJ(N)
    inc = np.array([w.update(row) for row in e])
    np.testing.assert_allclose(batch, ref, rtol=1e-10, equal_nan=True)
    np.testing.assert_allclose(inc, ref, rtol=1e-10, equal_nan=True)
    np.testing.assert_allclose(inc, batch, rtol=1e-12, equal_nan=True)
    assert np.isnan(ref).sum() == np.isnan(batch).sum() == np.isnan(inc).sum()


def test_resummation_stops_drift():
    """Huge residuals then tiny ones: without re-summing the running sum keeps the error
    of the huge phase (~1e8 * eps), which is large against J ~ 1e-6."""
    e = np.concatenate([np.full(5000, 1e4), np.full(5000, 1e-3)])
    e = e * (1 + 0.1 * np.sin(np.arange(10_000)))
    ref = naive.window_j(e * e, 50)
    for every in (7, 1000):
        w = WindowJ(50, resum_every=every)
        inc = np.array([w.update(float(v)) for v in e])
        np.testing.assert_allclose(inc[-2000:], ref[-2000:], rtol=1e-9)
        np.testing.assert_allclose(
            window_j(e, 50, resum_every=every)[-2000:], ref[-2000:], rtol=1e-9
        )


def test_reset_and_bad_window():
    w = WindowJ(1)
    w.update(1.0)
    w.update(1.0)
    assert w.ready
    w.reset()
    assert not w.ready and math.isnan(w.value) and math.isnan(w.update(2.0))
    with pytest.raises(ConfigError):
        WindowJ(-1)
    with pytest.raises(ConfigError):
        window_j(np.ones(3), 1, resum_every=0)
