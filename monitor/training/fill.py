"""Patterns lent by the reference model where a commissioned machine's own data has none.

Twenty minutes of commissioning cannot visit every manoeuvre an operator makes.  Where the
machine's own patterns are absent, its GRNN extrapolates from the nearest ones it has, J
jumps and the cross-fitted J0 that sets eps0 rests on one such event (2-25 x its
neighbours' on simulated machines).  The reference model of the same machine type was
trained on hours of every manoeuvre.  A machine within its tolerances behaves there much
as the reference does, which is a far better prediction than an extrapolation.  So the
reference's patterns are added, in the machine's own scaling, only where none of the
machine's own patterns lies within ``FILL_RADIUS_SIGMAS`` bandwidths: wherever the
machine has data, its own patterns decide (a kernel 3 bandwidths away weighs 1 % of one
on the spot).  Their counts are scaled by the ratio of the two models' training rows (and
rounded, at least one), so that an hour of reference data weighs what an hour of the
machine's own would.
"""

from __future__ import annotations

import numpy as np

from monitor.model.dgrnn import DGRNN
from monitor.model.modelfile import MonitorModel
from monitor.model.spec import Normalizer

#: A reference pattern is lent only this many bandwidths (sigma) or more away from every
#: pattern of the machine's own.
FILL_RADIUS_SIGMAS = 3.0


def _stats(norm: Normalizer, names: list[str]) -> tuple[np.ndarray, np.ndarray]:
    idx = [norm.names_.index(n) for n in names]
    return norm.mean_[idx], norm.std_[idx]


def lend_patterns(dgrnn: DGRNN, normalizer: Normalizer, reference: MonitorModel) -> int:
    """Add ``reference``'s patterns to the fitted ``dgrnn`` (scaled by ``normalizer``)
    where the machine's own are more than ``FILL_RADIUS_SIGMAS`` bandwidths away; the
    number lent.  The models must share a spec (``monitor.training.statistics.check_reference``)."""
    from scipy.spatial import cKDTree

    spec, own, ref = dgrnn.spec, dgrnn.grnn, reference.dgrnn.grnn
    fvar, _ = spec.feature_columns()
    feat_names = [spec.variables[v] for v in fvar]
    out_names = list(spec.outputs)
    # Reference z -> physical units -> this machine's z, per feature and per target.
    m_r, s_r = _stats(reference.normalizer, feat_names)
    m_o, s_o = _stats(normalizer, feat_names)
    patterns = (ref.patterns_ * s_r + m_r - m_o) / s_o
    tm_r, ts_r = _stats(reference.normalizer, out_names)
    tm_o, ts_o = _stats(normalizer, out_names)
    # Increment targets (spec.delta) are differences: scaled, never shifted.
    shift = np.where(spec.delta_mask().astype(bool), 0.0, tm_r - tm_o)
    targets = (ref.targets_ * ts_r + shift) / ts_o
    far = cKDTree(own.patterns_).query(patterns, k=1)[0] > FILL_RADIUS_SIGMAS * own.sigma_
    n = int(far.sum())
    if n == 0:
        return 0
    weight = float(own.counts_.sum()) / float(ref.counts_.sum())
    # Lent patterns get time indices past every own one: they are nobody's neighbours.
    start = int(own.pattern_index_.max()) + own.exclude_neighbours_ + 1
    own.patterns_ = np.ascontiguousarray(np.vstack([own.patterns_, patterns[far]]))
    own.targets_ = np.ascontiguousarray(np.vstack([own.targets_, targets[far]]))
    # Model files keep counts as whole numbers of rows: at least one each.
    lent_counts = np.maximum(1.0, np.rint(ref.counts_[far] * weight))
    own.counts_ = np.concatenate([own.counts_, lent_counts])
    own.pattern_index_ = np.concatenate([own.pattern_index_, start + np.arange(n, dtype=np.int64)])
    own.thinning_ = {**own.thinning_, "lent_from_reference": n}
    return n
