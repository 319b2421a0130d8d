"""Patterns lent by a reference model (monitor.training.fill): where the machine has no data
it predicts about as well as the reference does; where it has, as before."""

from __future__ import annotations

import numpy as np

from monitor.model.dgrnn import DGRNN, build_training_pairs
from monitor.model.grnn import GRNN
from monitor.model.modelfile import MonitorModel
from monitor.model.spec import DGRNNSpec, Normalizer
from monitor.model.threshold import ThresholdRule
from monitor.training.fill import FILL_RADIUS_SIGMAS, lend_patterns

# PP a level target, PA an increment target (spec.delta): both conversions are exercised.
SPEC = DGRNNSpec(
    outputs=("PP", "PA"),
    exogenous=("SpoolCmd",),
    lags=(("PA", (1,)), ("SpoolCmd", (0,))),
    delta=("PA",),
)


def _plant(spool: np.ndarray, pa0_bar: float = 50.0) -> np.ndarray:
    """A made-up loop, rows (PP, PA, SpoolCmd) in bar and %: PP follows the spool
    algebraically, PA relaxes towards a spool-dependent level."""
    n = len(spool)
    pa = np.empty(n)
    pa[0] = pa0_bar
    for k in range(1, n):
        pa[k] = pa[k - 1] + 0.2 * (40.0 + 1.2 * spool[k - 1] - pa[k - 1])
    pp = 60.0 + 1.5 * spool + 0.002 * spool**2
    return np.column_stack([pp, pa, spool])


def _fitted(data: np.ndarray, sigma: float) -> tuple[DGRNN, Normalizer]:
    norm = Normalizer(min_std={}).fit(data, SPEC.variables)
    grnn = GRNN(sigma=sigma, thinning="none", max_patterns=None, cluster_weights=False)
    return DGRNN(SPEC, grnn).fit(norm.transform(data)), norm


def _next_physical(dgrnn: DGRNN, norm: Normalizer, rows: np.ndarray) -> np.ndarray:
    """One-step predictions of (PP, PA) in bar for each row after the first."""
    X, _, t = build_training_pairs(SPEC, norm.transform(rows))
    z = dgrnn.grnn.predict(X)
    z[:, 1] += norm.transform(rows)[t - 1, 1]  # PA is an increment on its last value
    return norm.inverse_transform(np.column_stack([z, np.zeros(len(z))]))[:, :2]


def test_lent_patterns_predict_as_the_reference_where_the_machine_has_no_data() -> None:
    rng = np.random.default_rng(3)
    ref_data = _plant(np.repeat(rng.uniform(-100, 100, 400), 5))
    own_data = _plant(np.repeat(rng.uniform(-100, -20, 300), 5))  # never opened upwards
    reference, ref_norm = _fitted(ref_data, 0.08)
    ref_model = MonitorModel(reference, ref_norm, 10, ThresholdRule(), 1.0, 2.0)
    own, own_norm = _fitted(own_data, 0.08)
    probe_up = _plant(np.full(12, 70.0))  # where only the reference has data
    # Where the machine has its own data: -60 % held, PA at its level there (40 - 72 bar).
    probe_down = _plant(np.full(12, -60.0), pa0_bar=-32.0)
    truth_up = probe_up[1:, :2]
    before_up = _next_physical(own, own_norm, probe_up)
    before_down = _next_physical(own, own_norm, probe_down)
    n_own = own.grnn.patterns_.shape[0]

    lent = lend_patterns(own, own_norm, ref_model)

    assert 0 < lent < reference.grnn.patterns_.shape[0]
    assert own.grnn.patterns_.shape[0] == n_own + lent
    # Every lent pattern is far from the machine's own, in the machine's scaling.
    own_p = own.grnn.patterns_
    gap = np.linalg.norm(own_p[n_own:, None] - own_p[None, :n_own], axis=2)
    assert gap.min() > FILL_RADIUS_SIGMAS * own.grnn.sigma_
    # At +70 % spool the machine alone extrapolates from -20 %: PP about 140 bar low.
    assert np.abs(before_up - truth_up).max() > 50.0
    after_up = _next_physical(own, own_norm, probe_up)
    ref_up = _next_physical(reference, ref_norm, probe_up)
    # With the lent patterns it is as close to the plant as the reference itself is
    # (a kernel average over the same neighbours, under the machine's own bandwidth).
    assert np.abs(after_up - truth_up).max() < 2.0 * np.abs(ref_up - truth_up).max() + 1.0
    # Where the machine has its own data, nothing moves by more than 0.01 bar.
    np.testing.assert_allclose(_next_physical(own, own_norm, probe_down), before_down, atol=0.01)


def test_a_model_with_lent_patterns_survives_its_file(tmp_path) -> None:
    """Lent counts are whole numbers of rows (model files refuse anything else)."""
    from monitor.model.modelfile import load_model, save_model

    rng = np.random.default_rng(4)
    reference, ref_norm = _fitted(_plant(np.repeat(rng.uniform(-100, 100, 200), 5)), 0.08)
    own, own_norm = _fitted(_plant(np.repeat(rng.uniform(-100, -20, 150), 5)), 0.08)
    reference.grnn.counts_ = np.full(reference.grnn.patterns_.shape[0], 7.0)  # 7 rows each
    ref_model = MonitorModel(reference, ref_norm, 10, ThresholdRule(), 1.0, 2.0)
    n_own = own.grnn.patterns_.shape[0]
    lent = lend_patterns(own, own_norm, ref_model)
    # About 750 own rows against 7 x 1000: 7 rows each weigh 0.75, kept as 1.
    assert set(own.grnn.counts_[n_own:]) == {1.0} and lent > 0
    path = tmp_path / "m.npz"
    save_model(path, MonitorModel(own, own_norm, 10, ThresholdRule(), 1.0, 2.0))
    back = load_model(path).dgrnn.grnn
    np.testing.assert_array_equal(back.patterns_, own.grnn.patterns_)
    np.testing.assert_array_equal(back.counts_, own.grnn.counts_)
