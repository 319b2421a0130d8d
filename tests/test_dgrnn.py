"""Dynamic GRNN: lag embedding, multi-step prediction (eq. 7), live ticks, normalisation."""

from __future__ import annotations

import naive
import numpy as np
import pytest

from monitor.errors import ConfigError, InputFileError
from monitor.io.recording import Recording
from monitor.model.dgrnn import (
    DGRNN,
    TickPredictor,
    build_training_pairs,
    predict_series,
    predict_tick,
)
from monitor.model.grnn import GRNN
from monitor.model.spec import PRESETS, DGRNNSpec, Normalizer

SMALL = DGRNNSpec(
    outputs=("y1", "y2"),
    exogenous=("u",),
    lags=(("y1", (1, 2)), ("y2", (1,)), ("u", (0, 1, 3))),
)


def _loop(n=1500, seed=0, nan_every=0):
    """A small nonlinear second-order system driven by u, z-scored-ish."""
    rng = np.random.default_rng(seed)
    u = np.sin(np.arange(n) * 0.031) + 0.3 * np.sign(np.sin(np.arange(n) * 0.007))
    y1 = np.zeros(n)
    y2 = np.zeros(n)
    for t in range(2, n):
        y1[t] = 1.6 * y1[t - 1] - 0.7 * y1[t - 2] + 0.1 * u[t] + 0.05 * np.tanh(y2[t - 1])
        y2[t] = 0.9 * y2[t - 1] + 0.1 * y1[t - 1] ** 2 - 0.05 * u[t - 1]
    Z = np.column_stack([y1, y2, u]) + 0.002 * rng.standard_normal((n, 3))
    Z = (Z - Z.mean(0)) / Z.std(0)
    if nan_every:
        Z[nan_every::nan_every, rng.integers(0, 3)] = np.nan
    return Z


def _fitted(spec=SMALL, n=1500, **kw):
    kw.setdefault("sigma", 0.3)
    kw.setdefault("thinning", "none")
    return DGRNN(spec, GRNN(**kw)).fit(_loop(n))


# --------------------------------------------------------------------------- spec


def test_paper_preset_is_eq_11():
    spec = PRESETS["paper"]
    assert spec.outputs == ("QP",)
    assert spec.variables == ("QP", "PP", "PA", "PB")
    assert spec.features == (
        ("QP", 1),
        ("PP", 1),
        ("PA", 1),
        ("PB", 1),
        ("QP", 2),
        ("PP", 2),
        ("PA", 2),
        ("PB", 2),
    )
    assert spec.horizon == 1 and spec.max_lag == 2
    assert DGRNNSpec.preset("paper", horizon=5).horizon == 5


def test_default_preset():
    spec = DGRNNSpec.preset("default")
    assert spec.outputs == ("PP", "PA", "PB", "QP")
    assert set(spec.exogenous) == {"SpoolCmd", "PumpDispCmd", "EngineSpeed", "OilTemp"}
    assert ("SpoolCmd", 0) in spec.features and ("PA", 1) in spec.features
    assert not any(name == "PP" for name, _ in spec.features)  # PP is checked, not copied
    assert spec.delta == ("PA", "PB")
    assert all(lag >= 1 for name, lag in spec.features if name in spec.outputs)
    assert DGRNNSpec.from_dict(spec.to_dict()) == spec
    hash(spec)  # frozen and hashable


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"outputs": ("y",), "exogenous": (), "lags": (("y", (0, 1)),)}, ">= 1"),
        ({"outputs": ("y",), "exogenous": ("u",), "lags": (("v", (1,)),)}, "neither"),
        ({"outputs": ("y",), "exogenous": ("y",), "lags": (("y", (1,)),)}, "twice"),
        ({"outputs": ("y",), "exogenous": (), "lags": (("y", (1,)),), "horizon": 0}, "horizon"),
        ({"outputs": (), "exogenous": ("u",), "lags": (("u", (1,)),)}, "output"),
        ({"outputs": ("y",), "exogenous": ("u",), "lags": (("u", (-1,)),)}, ">= 0"),
        # A model file's header once held a null output name (found by tests/test_fuzz.py).
        ({"outputs": (None, "y"), "exogenous": (), "lags": (("y", (1,)),)}, "signal names"),
    ],
)
def test_spec_validation(kwargs, match):
    with pytest.raises(ConfigError, match=match):
        DGRNNSpec(**kwargs)
    with pytest.raises(ConfigError, match="unknown preset"):
        DGRNNSpec.preset("nope")


# --------------------------------------------------------------------------- embedding


def test_training_pairs_match_naive_and_skip_nan_windows():
    Z = _loop(300, nan_every=37)
    X, Y, t = build_training_pairs(SMALL, Z)
    Xn, Yn, tn = naive.embed(SMALL, Z)
    np.testing.assert_array_equal(t, tn)
    np.testing.assert_array_equal(X, Xn)
    np.testing.assert_array_equal(Y, Yn)
    assert len(t) < 300 - SMALL.max_lag  # some windows had a NaN
    assert not np.isnan(X).any()


def test_training_pairs_paper_order_by_hand():
    spec = PRESETS["paper"]
    Z = np.arange(20, dtype=float).reshape(5, 4)  # columns QP, PP, PA, PB
    X, Y, t = build_training_pairs(spec, Z)
    np.testing.assert_array_equal(t, [2, 3, 4])
    np.testing.assert_array_equal(X[0], [4, 5, 6, 7, 0, 1, 2, 3])  # row t-1, then row t-2
    np.testing.assert_array_equal(Y[:, 0], [8, 12, 16])


def test_too_few_rows_and_bad_columns():
    with pytest.raises(InputFileError, match="too few"):
        build_training_pairs(SMALL, np.zeros((3, 3)))
    with pytest.raises(InputFileError, match="3 columns"):
        build_training_pairs(SMALL, np.zeros((10, 4)))
    Z = _loop(100)
    Z[::2] = np.nan
    with pytest.raises(InputFileError, match="complete training window"):
        DGRNN(SMALL, GRNN(sigma=1.0)).fit(Z)


# --------------------------------------------------------------------------- prediction


def test_one_step_equals_grnn_on_embedded_rows():
    model = _fitted()
    Z = _loop(600, seed=3, nan_every=41)
    got = predict_series(model, Z, horizon=1, exact=True)
    X, _, t = build_training_pairs(SMALL, Z)
    want = np.full_like(got, np.nan)
    want[t] = model.grnn.predict(X)
    # Rows whose *inputs* are complete are predictable even if the current output is NaN.
    np.testing.assert_allclose(got[t], want[t], rtol=1e-12)
    naive_p1 = naive.multistep(SMALL, Z, model.grnn.patterns_, model.grnn.targets_, 0.3, 1)
    np.testing.assert_allclose(got, naive_p1, rtol=1e-10, atol=1e-12, equal_nan=True)
    assert np.isnan(got[: SMALL.max_lag]).all()


@pytest.mark.parametrize("p", [2, 3, 7])
def test_multistep_matches_naive(p):
    model = _fitted(n=800)
    Z = _loop(250, seed=4, nan_every=53)
    got = predict_series(model, Z, horizon=p, exact=True)
    want = naive.multistep(SMALL, Z, model.grnn.patterns_, model.grnn.targets_, 0.3, p)
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-12, equal_nan=True)
    assert np.isnan(got[: p - 1 + SMALL.max_lag]).all()
    assert np.isfinite(got[p - 1 + SMALL.max_lag]).all()


@pytest.mark.parametrize("p", [1, 4])
def test_clustered_model_matches_naive(p):
    model = _fitted(n=1500, thinning="min_distance", min_distance=0.3)
    g = model.grnn
    assert g.counts_.max() > 1  # the clusters really hold several rows
    Z = _loop(200, seed=5, nan_every=37)
    got = predict_series(model, Z, horizon=p, exact=True)
    want = naive.multistep(SMALL, Z, g.patterns_, g.targets_, 0.3, p, g.counts_)
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-12, equal_nan=True)
    ticks = TickPredictor(model, p, exact=True)
    rows = ticks.rows_needed
    for t in range(rows - 1, 200, 23):
        w = np.ascontiguousarray(Z[t - rows + 1 : t + 1])
        np.testing.assert_allclose(ticks.predict(w), got[t], rtol=1e-12, equal_nan=True)


def test_multistep_p2_hand_built():
    """y(t) = y(t-1) XOR u(t), learnt as a lookup table (sigma so small only exact hits count)."""
    spec = DGRNNSpec(outputs=("y",), exogenous=("u",), lags=(("y", (1,)), ("u", (0,))))
    P = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])  # [y(t-1), u(t)]
    T = np.array([[0.0], [1.0], [1.0], [0.0]])
    model = DGRNN(spec, GRNN.from_arrays(P, T, 0.01))
    y = [0, 0, 1, 1, 0]
    u = [0, 1, 1, 0, 1]
    Z = np.column_stack([y, u]).astype(float)
    p1 = predict_series(model, Z, horizon=1)[:, 0]
    p2 = predict_series(model, Z, horizon=2)[:, 0]
    # p = 1: f(y(t-1), u(t)) from measured y.
    np.testing.assert_array_equal(p1, [np.nan, 1, 1, 1, 0])
    # p = 2: y_hat(t-1) = f(y(t-2), u(t-1)), then y_hat(t) = f(y_hat(t-1), u(t)).
    #   t=2: y_hat(1) = 0^1 = 1, y_hat(2) = 1^1 = 0
    #   t=3: y_hat(2) = 0^1 = 1, y_hat(3) = 1^0 = 1
    #   t=4: y_hat(3) = 1^0 = 1, y_hat(4) = 1^1 = 0
    np.testing.assert_array_equal(p2, [np.nan, np.nan, 0, 1, 0])


def test_nan_pauses_only_the_predictions_that_read_it():
    spec = DGRNNSpec(outputs=("y",), exogenous=("u",), lags=(("y", (1,)), ("u", (0,))))
    model = DGRNN(spec, GRNN.from_arrays(np.eye(2), np.ones((2, 1)), 0.5))
    Z = np.ones((8, 2))
    Z[3, 0] = np.nan  # measured y(3): read by the prediction of t=4 (p=1)
    Z[6, 1] = np.nan  # u(6): read at t=6
    p1 = predict_series(model, Z, 1)[:, 0]
    assert np.isnan(p1[[0, 4, 6]]).all() and np.isfinite(p1[[1, 2, 3, 5, 7]]).all()
    p2 = predict_series(model, Z, 2)[:, 0]
    # p=2 reads measured y(t-2) and u(t-1), u(t): y(3) matters for t=5, u(6) for t=6 and 7.
    assert np.isnan(p2[[0, 1, 5, 6, 7]]).all() and np.isfinite(p2[[2, 3, 4]]).all()


@pytest.mark.parametrize("p", [1, 4])
def test_tick_predictor_equals_series(p):
    model = _fitted(n=800)
    Z = _loop(300, seed=7, nan_every=29)
    series = predict_series(model, Z, horizon=p)
    tick = TickPredictor(model, horizon=p)
    assert tick.rows_needed == p + SMALL.max_lag
    got = np.full_like(series, np.nan)
    for t in range(tick.rows_needed - 1, len(Z)):
        window = np.ascontiguousarray(Z[t - tick.rows_needed + 1 : t + 1])
        got[t] = tick.predict(window)
    np.testing.assert_array_equal(got, series)
    t = 150
    w = Z[t - tick.rows_needed + 1 : t + 1]
    np.testing.assert_array_equal(predict_tick(model, w, horizon=p), series[t])
    with pytest.raises(InputFileError, match="last"):
        tick.predict(Z[:2])


def test_fit_on_several_recordings_keeps_them_apart_in_time():
    g = GRNN(sigma=0.5, thinning="none", exclude_neighbours=20)
    model = DGRNN(SMALL, g).fit([_loop(200, seed=1), _loop(300, seed=2)])
    idx = g.pattern_index_
    assert len(idx) == (200 - 3) + (300 - 3)
    gap = idx[197] - idx[196]
    assert gap > 20
    with pytest.raises(ConfigError, match="not fitted"):
        predict_series(DGRNN(SMALL), _loop(50))
    assert model.spec is SMALL


def test_default_preset_end_to_end_loo():
    """The default preset on a synthetic stand-in for the loop: fits, predicts finite values."""
    rng = np.random.default_rng(0)
    n = 3000
    spec = DGRNNSpec.preset("default")
    spool = 60 * np.sin(np.arange(n) * 0.01)
    pa = np.convolve(np.maximum(spool, 0), np.ones(20) / 20, "same") + rng.normal(0, 0.3, n)
    pb = np.convolve(np.maximum(-spool, 0), np.ones(20) / 20, "same") + rng.normal(0, 0.3, n)
    pp = np.maximum(pa, pb) + 5 + rng.normal(0, 0.3, n)
    qp = np.abs(spool) / 3 + rng.normal(0, 0.1, n)
    raw = {
        "PP": pp,
        "PA": pa,
        "PB": pb,
        "QP": qp,
        "SpoolCmd": spool,
        "PumpDispCmd": np.full(n, 100.0),
        "EngineSpeed": np.full(n, 2200.0),
        "OilTemp": 40 + rng.normal(0, 0.01, n),
    }
    rec = Recording(np.arange(n) * 0.01, raw)
    norm = Normalizer().fit(rec, spec.variables)
    Z = norm.transform(rec, spec.variables)
    assert np.isfinite(Z).all()  # constant commands are scaled by their floors, not by 0
    model = DGRNN(spec, GRNN(max_patterns=800, loo_max_queries=500)).fit(Z[:2000])
    pred = predict_series(model, Z[2000:])
    assert pred.shape == (1000, 4) and np.isfinite(pred[2:]).all()
    assert np.mean((pred[2:] - Z[2002:, :4]) ** 2) < 0.05


# --------------------------------------------------------------------------- normaliser


def test_normalizer():
    rng = np.random.default_rng(0)
    A = rng.normal([10.0, -3.0, 200.0], [2.0, 0.5, 1e-6], size=(500, 3))
    A[7, 1] = np.nan
    names = ("PP", "x", "EngineSpeed")
    norm = Normalizer().fit(A, names)
    np.testing.assert_allclose(norm.mean_[:2], np.nanmean(A[:, :2], 0))
    np.testing.assert_allclose(norm.std_[:2], np.nanstd(A[:, :2], 0, ddof=1))
    assert norm.std_[2] == 10.0  # the floor
    Z = norm.transform(A)
    assert np.isnan(Z[7, 1]) and abs(np.nanmean(Z[:, 0])) < 1e-12
    np.testing.assert_allclose(norm.inverse_transform(Z), A, rtol=1e-12)
    np.testing.assert_allclose(norm.transform(A[:, [2, 0]], ["EngineSpeed", "PP"]), Z[:, [2, 0]])
    again = Normalizer.from_dict(norm.to_dict())
    np.testing.assert_array_equal(again.transform(A), Z)
    with pytest.raises(ConfigError, match="constant"):
        Normalizer().fit(np.ones((10, 1)), ["x"])
    with pytest.raises(InputFileError, match="fewer than 2"):
        Normalizer().fit(np.full((10, 1), np.nan), ["x"])
    with pytest.raises(ConfigError, match="no statistics"):
        norm.transform(A[:, :1], ["QP"])


SMALL_DELTA = DGRNNSpec(SMALL.outputs, SMALL.exogenous, SMALL.lags, delta=True)


def test_delta_targets_are_changes_and_round_trip():
    Z = _loop(300, seed=2)
    X, Y, t = build_training_pairs(SMALL_DELTA, Z)
    np.testing.assert_allclose(Y, Z[t, :2] - Z[t - 1, :2])
    nX, nY, nT = naive.embed(SMALL_DELTA, Z)
    np.testing.assert_allclose(Y, nY)
    assert DGRNNSpec.from_dict(SMALL_DELTA.to_dict()) == SMALL_DELTA
    with pytest.raises(ConfigError, match="lag 1"):
        DGRNNSpec(("y",), ("u",), (("y", (2,)), ("u", (0,))), delta=True)


@pytest.mark.parametrize("p", [1, 2, 5])
def test_delta_multistep_matches_naive(p):
    Z = _loop(800, seed=0)
    model = DGRNN(SMALL_DELTA, GRNN(sigma=0.3, thinning="none")).fit(Z)
    Zt = _loop(250, seed=4, nan_every=53)
    got = predict_series(model, Zt, horizon=p, exact=True)
    want = naive.multistep(SMALL_DELTA, Zt, model.grnn.patterns_, model.grnn.targets_, 0.3, p)
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-12, equal_nan=True)
    # The live path gives the same numbers.
    tick = TickPredictor(model, horizon=p, exact=True)
    n = tick.rows_needed
    for t in range(n, 250, 37):
        window = np.ascontiguousarray(Zt[t - n + 1 : t + 1])
        np.testing.assert_array_equal(tick.predict(window), got[t])


def test_delta_model_holds_an_unseen_level():
    """A level model can only return levels it saw; increments keep a held value held."""
    spec_level = DGRNNSpec(("y",), ("u",), (("y", (1, 2)), ("u", (0,))))
    spec_delta = DGRNNSpec(("y",), ("u",), (("y", (1, 2)), ("u", (0,))), delta=True)
    train = np.column_stack([np.repeat([0.0, 1.0, 2.0], 200), np.zeros(600)])
    test = np.column_stack([np.full(50, 5.0), np.zeros(50)])  # held at a level never seen
    for spec, expect in ((spec_level, 2.0), (spec_delta, 5.0)):
        model = DGRNN(spec, GRNN(sigma=0.5, thinning="none")).fit(train)
        assert predict_series(model, test)[10, 0] == pytest.approx(expect, abs=1e-6)


def test_delta_for_some_outputs_only_matches_naive():
    spec = DGRNNSpec(SMALL.outputs, SMALL.exogenous, SMALL.lags, delta=("y1",))
    assert list(spec.delta_mask()) == [1, 0]
    Z = _loop(800, seed=0)
    model = DGRNN(spec, GRNN(sigma=0.3, thinning="none")).fit(Z)
    X, Y, t = build_training_pairs(spec, Z)
    np.testing.assert_allclose(Y[:, 0], Z[t, 0] - Z[t - 1, 0])
    np.testing.assert_allclose(Y[:, 1], Z[t, 1])
    Zt = _loop(200, seed=5, nan_every=41)
    for p in (1, 3):
        got = predict_series(model, Zt, horizon=p, exact=True)
        want = naive.multistep(spec, Zt, model.grnn.patterns_, model.grnn.targets_, 0.3, p)
        np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-12, equal_nan=True)
    with pytest.raises(ConfigError, match="must be outputs"):
        DGRNNSpec(SMALL.outputs, SMALL.exogenous, SMALL.lags, delta=("u",))
