"""GRNN kernels against the plain-numpy reference and pyGRNN."""

from __future__ import annotations

import math
import warnings

import naive
import numpy as np
import pytest

from monitor.errors import ConfigError, InputFileError
from monitor.jit import FASTMATH
from monitor.model.grnn import GRNN
from monitor.model.grnn_core import cluster, grnn_predict, loo_errors, thin_min_distance


def _data(seed=0, n=300, nf=4, nout=2):
    rng = np.random.default_rng(seed)
    X = rng.standard_normal((n, nf))
    Y = np.column_stack([np.sin(X[:, 0]) + X[:, 1] * X[:, 2], np.cos(X[:, 3])][:nout])
    Y = Y + 0.05 * rng.standard_normal(Y.shape)
    return X, Y


def _series(seed=1, n=3000):
    """Autocorrelated 100 Hz-like data: smooth trajectories plus a little noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01
    X = np.column_stack([np.sin(1.1 * t), np.cos(0.37 * t), np.sin(2.3 * t + 1)])
    X += 0.02 * rng.standard_normal(X.shape)
    Y = np.sin(X[:, 0] + X[:, 1]) * X[:, 2] + 0.02 * rng.standard_normal(n)
    return X, Y


def test_fastmath_keeps_nan_and_inf_semantics():
    assert "nnan" not in FASTMATH and "ninf" not in FASTMATH
    assert {"nsz", "arcp", "contract", "afn", "reassoc"} == FASTMATH


@pytest.mark.parametrize("sigma", [0.05, 0.3, 1.0, 10.0])
def test_predict_matches_naive(sigma):
    X, Y = _data()
    Q = np.random.default_rng(5).standard_normal((57, 4)) * 1.5
    got = grnn_predict(Q, X, Y, sigma)
    want = naive.grnn_predict(Q, X, Y, sigma)
    assert got.shape == (57, 2)
    np.testing.assert_allclose(got, want, rtol=1e-11, atol=1e-12)


def test_far_away_queries_stay_finite():
    X, Y = _data(nout=1)
    far = X[:5] + 1e3
    sigma = 0.1
    assert np.isnan(naive.grnn_predict_unshifted(far, X, Y, sigma)).all()  # plain eq. 4: 0/0
    got = grnn_predict(far, X, Y, sigma)
    assert np.isfinite(got).all()
    np.testing.assert_allclose(got, naive.grnn_predict(far, X, Y, sigma), rtol=1e-11)
    # So far out, the nearest pattern dominates completely.
    d = ((far[:, None, :] - X[None]) ** 2).sum(2)
    np.testing.assert_allclose(got[:, 0], Y[d.argmin(1), 0], rtol=1e-12)


def test_duplicate_patterns_and_exact_hits():
    X, Y = _data(n=50)
    Xd = np.vstack([X, X[:10]])
    Yd = np.vstack([Y, Y[:10] + 1.0])  # same inputs, different targets
    for sigma in (1e-3, 0.5):
        got = grnn_predict(Xd[:20], Xd, Yd, sigma)
        np.testing.assert_allclose(got, naive.grnn_predict(Xd[:20], Xd, Yd, sigma), rtol=1e-11)
    # With a tiny sigma an exact duplicate hit averages the duplicates' targets.
    got = grnn_predict(X[:10], Xd, Yd, 1e-4)
    np.testing.assert_allclose(got, Y[:10] + 0.5, rtol=1e-12)


def test_nan_query_gives_nan_row():
    X, Y = _data()
    Q = X[:3].copy()
    Q[1, 2] = np.nan
    got = grnn_predict(Q, X, Y, 0.5)
    assert np.isnan(got[1]).all() and np.isfinite(got[[0, 2]]).all()


def test_matches_pygrnn():
    pygrnn = pytest.importorskip("pyGRNN")
    X, Y = _data(nout=1, n=200)
    Q = np.random.default_rng(9).standard_normal((40, 4))
    for sigma in (0.3, 0.7, 2.0):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ref = pygrnn.GRNN(kernel="RBF", sigma=sigma, calibration="None")
            ref.fit(X, Y[:, 0])
            want = ref.predict(Q)
        # Only where pyGRNN's own kernel sum does not underflow.
        dens = np.exp(-((Q[:, None] - X[None]) ** 2).sum(2) / (2 * sigma**2)).sum(1)
        ok = dens > 1e-250
        assert ok.sum() > 30
        np.testing.assert_allclose(grnn_predict(Q, X, Y, sigma)[ok, 0], want[ok], rtol=1e-9)
        model = GRNN(sigma=sigma, thinning="none").fit(X, Y[:, 0])
        np.testing.assert_allclose(model.predict(Q)[ok], want[ok], rtol=1e-9)


# --------------------------------------------------------------------------- LOO


@pytest.mark.parametrize("m", [0, 3, 25])
def test_loo_errors_match_naive(m):
    X, Y = _series(n=400)
    idx = np.arange(400)
    # Every row its own pattern: plain LOO of eq. 4.
    got = loo_errors(idx, X, Y, idx, 0.2, m)
    want = naive.loo_errors(X, Y, idx, X, Y, idx, 0.2, m)
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-14)


def test_loo_errors_with_separate_queries_and_gaps():
    X, Y = _series(n=300)
    qidx = np.arange(0, 300, 7)
    pidx = np.arange(0, 300, 3)
    pidx = pidx + (pidx >= 150) * 1000  # a second "recording" far away in time
    qidx2 = qidx + (qidx >= 150) * 1000
    tidx = np.arange(300) + (np.arange(300) >= 150) * 1000
    assign = np.where(np.arange(300) % 3 == 0, np.arange(300) // 3, -1)  # strided patterns
    got = loo_errors(qidx, X, Y, assign, 0.3, 10, tidx)
    want = naive.loo_errors(X[qidx], Y[qidx], qidx2, X[::3], Y[::3], pidx, 0.3, 10)
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-14)


def test_loo_with_no_eligible_pattern_is_nan():
    X, Y = _series(n=10)
    got = loo_errors(np.arange(10), X, Y, np.arange(10), 0.3, 100)
    assert np.isnan(got).all()
    with pytest.raises(ConfigError, match="exclude_neighbours"):
        GRNN(exclude_neighbours=100, thinning="none").fit(X, Y)


def test_loo_sigma_is_a_minimum_and_neighbour_exclusion_widens_it():
    X, Y = _series(n=2000)
    fitted = GRNN(exclude_neighbours=50, thinning="none", loo_max_queries=500).fit(X, Y)
    q = np.unique(np.linspace(0, 1999, 500).round().astype(int))
    idx = np.arange(2000)

    def loss(s):
        return np.nanmean(naive.loo_errors(X[q], Y[q], idx[q], X, Y, idx, s, 50))

    best = loss(fitted.sigma_)
    assert best == pytest.approx(fitted.loo_error_, rel=1e-9)
    for factor in (0.5, 0.8, 1.25, 2.0):
        assert best <= loss(fitted.sigma_ * factor) + 1e-12
    plain = GRNN(exclude_neighbours=0, thinning="none", loo_max_queries=500).fit(X, Y)
    assert plain.sigma_ < fitted.sigma_  # autocorrelation alone pulls plain LOO down
    assert fitted.sigma_rule_ == "loo" and fitted.exclude_neighbours_ == 50


# --------------------------------------------------------------------------- thinning


def test_thinning_matches_naive_and_respects_radius():
    X, _ = _series(n=1500)
    for r in (0.05, 0.2):
        kept = thin_min_distance(X, r)
        np.testing.assert_array_equal(kept, naive.thin_min_distance(X, r))
        d = np.sqrt(((X[kept][:, None] - X[kept][None]) ** 2).sum(2))
        assert (d[np.triu_indices(len(kept), 1)] > r).all()
    assert thin_min_distance(X, 0.05, max_keep=5) is None


def test_thinning_bounds_pattern_count_and_is_recorded():
    X, Y = _series(n=3000)
    g = GRNN(sigma=0.3, min_distance=0.001, max_patterns=200).fit(X, Y)
    assert 150 <= g.patterns_.shape[0] <= 200  # the radius is bisected up to the bound
    info = g.thinning_
    assert info["rule"] == "min_distance" and info["min_distance"] > 0.001
    assert info["n_rows"] == 3000 and info["n_patterns"] == g.patterns_.shape[0]
    assert info["weights"] == "cluster_counts" and g.counts_.sum() == 3000
    # Every row joins its nearest kept row; a cluster is its members' mean input and mean
    # target (brute force here).
    near = ((X[:, None] - X[g.pattern_index_][None]) ** 2).sum(2).argmin(1)
    for i in range(len(g.patterns_)):
        np.testing.assert_allclose(g.patterns_[i], X[near == i].mean(0), rtol=1e-12, atol=1e-15)
        assert g.targets_[i, 0] == pytest.approx(Y[near == i].mean(), rel=1e-12, abs=1e-15)
    np.testing.assert_array_equal(g.counts_, np.bincount(near))
    # Two seeds at one place: every row there joins the first (argmin's rule); a row with a
    # NaN joins seed 0, as a full scan (no distance is below NaN) leaves it.
    seeds = X[g.pattern_index_]
    twin = np.vstack([seeds[:3], seeds[1:2], seeds[3:]])
    Xn = X.copy()
    Xn[7, 0] = np.nan
    assign = cluster(Xn, Y[:, None], twin)[0]
    want = ((Xn[:, None] - twin[None]) ** 2).sum(2).argmin(1)
    want[7] = 0
    np.testing.assert_array_equal(assign, want)
    assert 3 not in assign and (assign == 1).any()
    plain = GRNN(sigma=0.3, min_distance=0.001, max_patterns=200, cluster_weights=False)
    plain.fit(X, Y)
    np.testing.assert_array_equal(plain.pattern_index_, g.pattern_index_)  # same seeds
    np.testing.assert_array_equal(plain.patterns_, X[plain.pattern_index_])
    np.testing.assert_array_equal(plain.targets_[:, 0], Y[plain.pattern_index_])
    assert (plain.counts_ == 1).all() and plain.thinning_["weights"] == "none"
    s = GRNN(sigma=0.3, thinning="stride", stride=7, max_patterns=None).fit(X, Y)
    np.testing.assert_array_equal(s.pattern_index_, np.arange(0, 3000, 7))
    np.testing.assert_array_equal(s.targets_[:, 0], Y[::7])  # strided rows count once each
    assert (s.counts_ == 1).all() and s.thinning_["weights"] == "none"
    with pytest.raises(ConfigError, match="max_patterns"):
        GRNN(sigma=0.3, thinning="stride", stride=2, max_patterns=100).fit(X, Y)


def test_duplicate_rows_are_thinned_away():
    X, Y = _data(n=30)
    Xd, Yd = np.vstack([X, X]), np.vstack([Y, Y])
    g = GRNN(sigma=0.5, min_distance=0.0).fit(Xd, Yd)
    assert g.patterns_.shape[0] == 30


def test_clustered_prediction_is_eq4_over_rows_moved_to_their_centres():
    X, Y = _series(n=1200)
    g = GRNN(sigma=0.15, min_distance=0.1).fit(X, Y)
    Q = np.vstack([X[::37] + 0.01, X[:3] + 50.0])  # near and far-away queries
    want = naive.grnn_predict_counts(Q, g.patterns_, g.targets_, g.counts_, 0.15)
    np.testing.assert_allclose(g.predict(Q), want[:, 0], rtol=1e-10, atol=1e-13)
    reps = g.counts_.astype(int)
    moved = naive.grnn_predict(
        Q[:-3], np.repeat(g.patterns_, reps, 0), np.repeat(g.targets_, reps, 0), 0.15
    )
    np.testing.assert_allclose(g.predict(Q[:-3]), moved[:, 0], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(
        grnn_predict(Q, g.patterns_, g.targets_, 0.15, g.counts_), want, rtol=1e-10, atol=1e-13
    )


def test_a_hold_outweighs_a_transient_passing_close_by():
    # 2000 rows of a hold at x = 0 (target 0) and a 20-row ramp through it (target 1).
    ramp = np.linspace(-0.5, 0.5, 20)
    X = np.concatenate([np.zeros(2000), ramp])[:, None]
    Y = np.concatenate([np.zeros(2000), np.ones(20)])
    g = GRNN(sigma=0.2, min_distance=0.04).fit(X, Y)
    # By hand: the two ramp rows within 0.04 of 0 join the hold's centre (2002 members,
    # mean 2/2002); the other 18 ramp rows are centres of their own with weight exp(-d).
    far = ramp[np.abs(ramp) > 0.04]
    s = np.exp(-(far**2) / (2 * 0.2**2)).sum()
    assert len(g.patterns_) == 19
    assert g.predict(np.zeros((1, 1)))[0] == pytest.approx((2 + s) / (2002 + s), rel=1e-12)
    # The same centres counted once each would call the hold a ramp.
    flat = GRNN.from_arrays(g.patterns_, g.targets_, 0.2)
    assert flat.predict(np.zeros((1, 1)))[0, 0] > 0.8


@pytest.mark.parametrize(("m", "sigma"), [(0, 0.2), (5, 0.2), (40, 0.2), (5, 0.02)])
def test_cluster_loo_matches_naive(m, sigma):
    # sigma 0.02: most clusters' weights underflow to exactly 0 beside the nearest.
    X, Y = _series(n=500)
    assign, counts, _, _ = cluster(X, Y[:, None], X[thin_min_distance(X, 0.15)])
    tidx = np.arange(500) + (np.arange(500) >= 250) * 1000
    rows = np.arange(0, 500, 9)
    got = loo_errors(rows, X, Y, assign, sigma, m, tidx)
    want = naive.cluster_loo_errors(rows, X, Y, tidx, assign, sigma, m)
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-14)
    assert counts.sum() == 500


# --------------------------------------------------------------------------- estimator API


def test_fit_predict_api_and_shapes():
    X, Y = _data()
    g = GRNN(sigma=0.4, thinning="none")
    assert g.sigma == 0.4 and not hasattr(g, "patterns_")  # __init__ only stores
    g.fit(X, Y)
    assert g.sigma_ == 0.4 and g.sigma_rule_ == "fixed" and math.isnan(g.loo_error_)
    assert g.predict(X[:5]).shape == (5, 2)
    assert g.predict(X[0]).shape == (2,)
    g1 = GRNN(sigma=0.4, thinning="none").fit(X, Y[:, 0])
    assert g1.predict(X[:5]).shape == (5,)
    np.testing.assert_allclose(g1.predict(X[:5]), g.predict(X[:5])[:, 0], rtol=1e-13)
    before = g.predict(X[:7]).copy()
    g.predict(X[7:20])
    np.testing.assert_array_equal(g.predict(X[:7]), before)  # predict is pure


def test_from_arrays_round_trip():
    X, Y = _series(n=800)
    g = GRNN(min_distance=0.05).fit(X, Y)
    h = GRNN.from_arrays(
        g.patterns_,
        g.targets_,
        g.sigma_,
        counts_=g.counts_,
        sigma_rule_=g.sigma_rule_,
        thinning_=g.thinning_,
        loo_error_=g.loo_error_,
        pattern_index_=g.pattern_index_,
        exclude_neighbours_=50,
    )
    np.testing.assert_array_equal(h.predict(X[:50]), g.predict(X[:50])[:, None])
    assert h.sigma_rule_ == "loo" and h.thinning_ == g.thinning_


@pytest.mark.parametrize(
    "X, Y, match",
    [
        (np.ones((5, 2)), np.ones(4), "rows"),
        (np.ones((1, 2)), np.ones(1), "at least 2"),
        (np.ones((5, 2, 2)), np.ones(5), "2-D"),
        (np.array([[0.0, 1.0], [np.nan, 2.0], [1.0, 1.0]]), np.ones(3), "row 1"),
        (np.array([[0.0, 1.0], [np.inf, 2.0], [1.0, 1.0]]), np.ones(3), "non-finite"),
        (np.ones((3, 2)), np.array([1.0, np.nan, 2.0]), "Y has a non-finite"),
    ],
)
def test_fit_rejects_bad_data(X, Y, match):
    with pytest.raises(InputFileError, match=match):
        GRNN(sigma=1.0).fit(X, Y)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"sigma": -1.0},
        {"sigma": float("nan")},
        {"sigma_rule": "magic"},
        {"sigma_rule": "fixed"},
        {"thinning": "random"},
        {"stride": 0},
        {"exclude_neighbours": -1},
        {"max_patterns": 1},
        {"sigma_bounds": (1.0, 0.5)},
    ],
)
def test_fit_rejects_bad_params(kwargs):
    X, Y = _data()
    with pytest.raises(ConfigError):
        GRNN(**kwargs).fit(X, Y)


def test_predict_checks():
    X, Y = _data()
    with pytest.raises(ConfigError, match="not fitted"):
        GRNN().predict(X)
    g = GRNN(sigma=1.0).fit(X, Y)
    with pytest.raises(InputFileError, match="4 features"):
        g.predict(np.ones((3, 5)))
    with pytest.raises(ConfigError, match="strictly increasing"):
        GRNN(sigma=1.0).fit(X, Y, time_index=np.zeros(len(X), dtype=int))
