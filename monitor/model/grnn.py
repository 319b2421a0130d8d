"""Specht's general regression neural network (He & He 2014, eq. 4), numba-compiled.

    y_hat(x) = sum_i y_i exp(-d_i) / sum_i exp(-d_i),   d_i = |x - x_i|^2 / (2 sigma^2)

Inputs are already z-scored (see ``monitor.model.spec.Normalizer``); everything is float64.

Pattern selection keeps the count bounded (``thinning``).  With ``min_distance`` thinning the
GRNN is Specht's (1991) clustered form: every training row joins its nearest kept row, and
the cluster, placed at its members' mean input ``x_i`` with their mean target ``y_i``,
weighs ``c_i exp(-d_i)`` for ``c_i`` members.  That is eq. 4 over the training rows with
each row moved to its cluster's centroid, so the pattern set stays small but still knows
how often the machine sat where: a hold (thousands of rows in one cluster) outweighs the few
rows of a transient passing close by.
Unthinned or strided patterns each count once, which is eq. 4 exactly.  Kernels take
``logw = log(c)`` and fold it into the exponent.

Numerical stability: every weight is computed as ``exp(d_min - d_i)`` with ``d_min`` the
smallest (log-weighted) distance of that query.  The common factor cancels between numerator
and denominator, so the value is eq. 4 exactly, but the dominant pattern always weighs 1: the
denominator is >= 1 and a query far from every pattern (where every plain ``exp(-d_i)``
underflows to 0 and eq. 4 would be 0/0) returns the target of its nearest pattern(s).

Layout (stumpy style): public functions validate and call a parallel ``@njit`` driver that
loops over queries with ``prange``; the per-query work is a small serial kernel
(``monitor.model.grnn_index.cutoff_row``) that the dynamic model (``monitor.model.dgrnn``) reuses.
Exact eq. 4 runs it over every pattern (``exact_index``); the detector by default sums only
the patterns within a cut-off radius with a stated error bound (``build_index``).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

from monitor.errors import ConfigError, InputFileError
from monitor.model.grnn_core import (
    _LOO_MAX_ENTRIES,
    SIGMA_RULES,
    THINNING_RULES,
    Bandwidth,
    PatternSet,
    _as_matrix,
    _check_counts,
    _check_sigma,
    _check_time_index,
    _loo_errors,
    _loo_setup,
    _require_finite,
    cluster,
    n_chunks,
    thin_min_distance,
)
from monitor.model.grnn_index import CutoffIndex, build_index, exact_index, predict_cutoff

# --------------------------------------------------------------------------- estimator


class GRNN:
    """GRNN regressor, scikit-learn style: ``__init__`` stores parameters, ``fit`` learns.

    Parameters
    ----------
    sigma : fixed bandwidth; when given it is used as is (``sigma_rule_ == "fixed"``).
    sigma_rule : ``"loo"``: choose sigma by leave-one-out on the training rows, leaving out
        every pattern within ``exclude_neighbours`` samples in time (at 100 Hz neighbouring
        rows are nearly copies, and plain LOO would pick a sigma that only interpolates
        between them).  ``"fixed"`` requires ``sigma``.
    thinning : ``"none"``, ``"stride"`` (every ``stride``-th row) or ``"min_distance"``
        (after the stride, greedy in time order: keep a row only if farther than
        ``min_distance`` from all kept rows; if more than ``max_patterns`` would stay, the
        radius is doubled until the bound holds and then bisected so the count ends close to
        it; the radius used is recorded).  The kept rows seed clusters: every training row
        joins its nearest seed, and the pattern is the cluster's mean input and mean target,
        weighted by its member count (Specht's clustered GRNN; see the module docstring).
        The seeds cover the data evenly, so rare transients keep their own patterns; the
        counts keep the density.  With ``none`` and ``stride`` each kept row is a pattern
        that counts once (eq. 4 exactly).
    loo_max_queries : the LOO error is evaluated on at most this many training rows (evenly
        spread in time), each predicted from the clusters with its temporal neighbours
        taken out.
    sigma_bounds : (lo, hi) for the search; default from the data's distance scale.
    cluster_weights : with ``min_distance`` thinning, ``False`` keeps the seed rows as plain
        patterns (own input and target, count 1: eq. 4 over the kept rows, as pyGRNN would
        compute it); the default ``True`` is the clustered form.

    Fitted attributes: ``pattern_set_`` (``PatternSet``: ``patterns_``, ``targets_``,
    ``counts_`` members per pattern, ``pattern_index_`` time index of each pattern's seed
    row), ``bandwidth_`` (``Bandwidth``: ``sigma_``, ``sigma_rule_``, ``loo_error_`` NaN when
    fixed, ``exclude_neighbours_``), ``thinning_`` (dict: rule, stride, min_distance
    actually used, rows in, patterns kept, weights), ``n_features_in_``, ``n_outputs_``.
    """

    def __init__(
        self,
        sigma: float | None = None,
        sigma_rule: str = "loo",
        exclude_neighbours: int = 50,
        thinning: str = "min_distance",
        min_distance: float = 0.05,
        stride: int = 1,
        max_patterns: int | None = 3000,
        loo_max_queries: int = 2000,
        sigma_bounds: tuple[float, float] | None = None,
        cluster_weights: bool = True,
    ) -> None:
        self.sigma = sigma
        self.sigma_rule = sigma_rule
        self.exclude_neighbours = exclude_neighbours
        self.thinning = thinning
        self.min_distance = min_distance
        self.stride = stride
        self.max_patterns = max_patterns
        self.loo_max_queries = loo_max_queries
        self.sigma_bounds = sigma_bounds
        self.cluster_weights = cluster_weights

    # -- parameters ---------------------------------------------------------------------

    def _check_params(self) -> None:
        if self.sigma is None and self.sigma_rule not in SIGMA_RULES:
            raise ConfigError(f"sigma_rule must be one of {SIGMA_RULES}, got {self.sigma_rule!r}")
        if self.sigma is None and self.sigma_rule == "fixed":
            raise ConfigError("sigma_rule='fixed' needs a sigma")
        if self.sigma is not None:
            _check_sigma(self.sigma)
        if self.thinning not in THINNING_RULES:
            raise ConfigError(f"thinning must be one of {THINNING_RULES}, got {self.thinning!r}")
        if int(self.exclude_neighbours) < 0:
            raise ConfigError("exclude_neighbours must be >= 0")
        if int(self.stride) < 1:
            raise ConfigError("stride must be >= 1")
        if self.max_patterns is not None and int(self.max_patterns) < 2:
            raise ConfigError("max_patterns must be >= 2 (or None for no bound)")
        if not (self.min_distance >= 0 and math.isfinite(self.min_distance)):
            raise ConfigError("min_distance must be a finite number >= 0")
        if int(self.loo_max_queries) < 1:
            raise ConfigError("loo_max_queries must be >= 1")
        if self.sigma_bounds is not None:
            lo, hi = (float(v) for v in self.sigma_bounds)
            if not (0 < lo < hi < math.inf):
                raise ConfigError(f"sigma_bounds must be 0 < lo < hi, got {self.sigma_bounds}")

    # -- fit ----------------------------------------------------------------------------

    def fit(self, X: Any, Y: Any, time_index: Any = None) -> GRNN:
        """Store (thinned) patterns and choose sigma.

        ``time_index`` (strictly increasing integers, default 0..n-1) places each row in
        time; to fit on several recordings, offset each recording's index by more than
        ``exclude_neighbours`` so rows of different recordings are never neighbours.
        """
        self._check_params()
        Xa = _as_matrix(X, "X")
        y1d = np.asarray(Y).ndim == 1
        Ya = _as_matrix(Y, "Y")
        if Xa.shape[0] != Ya.shape[0]:
            raise InputFileError(f"X has {Xa.shape[0]} rows but Y has {Ya.shape[0]}")
        if Xa.shape[0] < 2:
            raise InputFileError(f"a GRNN needs at least 2 training patterns, got {Xa.shape[0]}")
        if Xa.shape[1] < 1 or Ya.shape[1] < 1:
            raise InputFileError("X and Y need at least one column each")
        _require_finite(Xa, "X")
        _require_finite(Ya, "Y")
        tidx = _check_time_index(time_index, Xa.shape[0])

        keep, thinning = self._thin(Xa)
        P, pidx = np.ascontiguousarray(Xa[keep]), tidx[keep]
        clustered = thinning["rule"] == "min_distance" and bool(self.cluster_weights)
        if clustered:
            assign, counts, P, Py = cluster(Xa, Ya, P)
        else:  # each kept row is its own pattern; the rows between strides belong to none
            assign = np.full(Xa.shape[0], -1, dtype=np.int64)
            assign[keep] = np.arange(len(keep))
            counts, Py = np.ones(len(keep)), Ya[keep]
        thinning["weights"] = "cluster_counts" if clustered else "none"

        if self.sigma is not None:
            sigma, rule, loo = _check_sigma(self.sigma), "fixed", math.nan
        else:
            sigma, loo = self._loo_sigma(Xa, Ya, tidx, assign)
            rule = "loo"

        self.pattern_set_ = PatternSet(P, np.ascontiguousarray(Py), counts, pidx)
        self.bandwidth_ = Bandwidth(float(sigma), rule, float(loo), int(self.exclude_neighbours))
        self.thinning_ = thinning
        self._y1d = y1d
        return self

    # -- fitted attributes (scikit-learn's names, each a field of the records above) ------

    @property
    def patterns_(self) -> np.ndarray:
        return self.pattern_set_.patterns

    @patterns_.setter
    def patterns_(self, value: np.ndarray) -> None:
        self.pattern_set_ = replace(self.pattern_set_, patterns=value)

    @property
    def targets_(self) -> np.ndarray:
        return self.pattern_set_.targets

    @targets_.setter
    def targets_(self, value: np.ndarray) -> None:
        self.pattern_set_ = replace(self.pattern_set_, targets=value)

    @property
    def counts_(self) -> np.ndarray:
        return self.pattern_set_.counts

    @counts_.setter
    def counts_(self, value: np.ndarray) -> None:
        self.pattern_set_ = replace(self.pattern_set_, counts=value)

    @property
    def pattern_index_(self) -> np.ndarray:
        return self.pattern_set_.index

    @pattern_index_.setter
    def pattern_index_(self, value: np.ndarray) -> None:
        self.pattern_set_ = replace(self.pattern_set_, index=value)

    @property
    def n_features_in_(self) -> int:
        return int(self.pattern_set_.patterns.shape[1])

    @property
    def n_outputs_(self) -> int:
        return int(self.pattern_set_.targets.shape[1])

    @property
    def sigma_(self) -> float:
        return self.bandwidth_.sigma

    @property
    def sigma_rule_(self) -> str:
        return self.bandwidth_.rule

    @property
    def loo_error_(self) -> float:
        return self.bandwidth_.loo_error

    @property
    def exclude_neighbours_(self) -> int:
        return self.bandwidth_.exclude_neighbours

    def _thin(self, X: np.ndarray) -> tuple[np.ndarray, dict[str, Any]]:
        n = X.shape[0]
        stride = int(self.stride) if self.thinning != "none" else 1
        idx = np.arange(0, n, stride, dtype=np.int64)
        radius = 0.0
        if self.thinning == "min_distance":
            radius = float(self.min_distance)
            cap = len(idx) if self.max_patterns is None else int(self.max_patterns)
            sub = np.ascontiguousarray(X[idx])
            kept = thin_min_distance(sub, radius, cap)
            if kept is None:
                # Too many patterns: double the radius until the bound holds, then bisect
                # (log scale) so the count ends close to max_patterns, not far below it.
                lo, hi = radius, max(radius, 1e-3)
                while kept is None:
                    lo, hi = hi, hi * 2.0
                    kept = thin_min_distance(sub, hi, cap)
                for _ in range(6):
                    mid = math.sqrt(lo * hi) if lo > 0 else hi / 2.0
                    trial = thin_min_distance(sub, mid, cap)
                    if trial is None:
                        lo = mid
                    else:
                        hi, kept = mid, trial
                radius = hi
            idx = idx[kept]
        elif self.max_patterns is not None and len(idx) > int(self.max_patterns):
            raise ConfigError(
                f"{len(idx)} patterns exceed max_patterns={self.max_patterns}: raise the stride"
                " or use thinning='min_distance'"
            )
        info = {
            "rule": self.thinning,
            "stride": stride,
            "min_distance": radius,
            "max_patterns": self.max_patterns,
            "n_rows": n,
            "n_patterns": int(len(idx)),
        }
        return idx, info

    def _loo_sigma(self, X, Y, tidx, assign) -> tuple[float, float]:
        n = X.shape[0]
        n_clusters = int(assign.max()) + 1
        nq = min(n, int(self.loo_max_queries), max(1, _LOO_MAX_ENTRIES // n_clusters))
        q = np.unique(np.linspace(0, n - 1, nq).round().astype(np.int64))
        m = int(self.exclude_neighbours)
        args = _loo_setup(q, X, Y, tidx, m, assign)
        if np.isnan(_loo_errors(*args, 1.0, n_chunks())).all():
            raise ConfigError(
                f"leave-one-out has nothing to compare: every pattern is within "
                f"exclude_neighbours={m} samples of every query; record more data or lower it"
            )

        def loss(log_sigma: float) -> float:
            s = math.exp(log_sigma)
            return float(np.nanmean(_loo_errors(*args, 0.5 / (s * s), n_chunks())))

        if self.sigma_bounds is not None:
            lo, hi = (float(v) for v in self.sigma_bounds)
        else:
            # Scale of the data: median distance between queries and patterns.
            finite = args[0][np.isfinite(args[0])]
            scale = math.sqrt(float(np.median(finite))) if finite.size else 1.0
            scale = scale if scale > 0 else 1.0
            lo, hi = scale * 1e-3, scale * 3.0
        # Coarse log grid first (the LOO curve can have shallow local minima), then Brent
        # on the bracket around the best grid point.
        grid = np.linspace(math.log(lo), math.log(hi), 29)
        vals = np.array([loss(g) for g in grid])
        k = int(np.nanargmin(vals))
        a, b = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
        # Imported here: scipy.optimize costs the daemon's start-up (predict only) ~1 s on
        # the host and far more on a small controller; only fitting needs it.
        from scipy.optimize import minimize_scalar

        res = minimize_scalar(loss, bounds=(a, b), method="bounded", options={"xatol": 1e-3})
        best_log, best_val = (res.x, res.fun) if res.fun <= vals[k] else (grid[k], vals[k])
        return math.exp(best_log), float(best_val)

    # -- predict ------------------------------------------------------------------------

    def _check_fitted(self) -> None:
        if not hasattr(self, "patterns_"):
            raise ConfigError("this GRNN is not fitted yet: call fit(X, Y) first")

    def cutoff_index(self, exact: bool = False) -> CutoffIndex:
        """The kd-tree and cut-off of ``monitor.model.grnn_index`` over the fitted patterns (error
        <= 1e-6 of each target's std), or with ``exact`` a one-leaf brute-force "index".

        Built on first use and kept until the patterns change (not stored in model files).
        """
        self._check_fitted()
        cache = self.__dict__.setdefault("_indexes", {})
        # The entry keeps the arrays it was built from: a refit (new arrays) rebuilds it.
        built = cache.get(exact)
        arrays = (self.patterns_, self.targets_, self.counts_)
        if built is None or any(a is not b for a, b in zip(built[0], arrays, strict=True)):
            make = exact_index if exact else build_index
            built = (arrays, make(*arrays))
            cache[exact] = built
        return built[1]

    def predict(self, X: Any, exact: bool = True) -> np.ndarray:
        """Eq. 4 for each row of X; a row with NaN gives NaN.  Shape (n,) if fitted on 1-D Y.

        ``exact=False`` sums only the patterns within the cut-off of ``cutoff_index``.
        """
        self._check_fitted()
        Xa = np.asarray(X, dtype=np.float64)
        single = Xa.ndim == 1
        if single:
            Xa = Xa[None, :]
        if Xa.ndim != 2 or Xa.shape[1] != self.n_features_in_:
            raise InputFileError(
                f"X must have {self.n_features_in_} features per row, got shape {np.shape(X)}"
            )
        Xa = np.ascontiguousarray(Xa)
        out = predict_cutoff(self.cutoff_index(exact), Xa, self.sigma_, n_chunks())
        if self._y1d:
            out = out[:, 0]
        return out[0] if single else out

    @classmethod
    def from_arrays(cls, patterns: Any, targets: Any, sigma: float, **fitted: Any) -> GRNN:
        """Rebuild a fitted GRNN (e.g. from a model file) without refitting.

        ``fitted`` may carry the recorded attributes (``counts_``, ``sigma_rule_``,
        ``thinning_``, ``loo_error_``, ``pattern_index_``, ``exclude_neighbours_``).
        """
        P = _as_matrix(patterns, "patterns")
        Y = _as_matrix(targets, "targets")
        if P.shape[0] != Y.shape[0] or P.shape[0] < 1:
            raise InputFileError("patterns and targets must have the same, non-zero row count")
        _require_finite(P, "patterns")
        _require_finite(Y, "targets")
        model = cls(sigma=_check_sigma(sigma))
        counts = _check_counts(fitted.pop("counts_", None), P.shape[0])
        index = np.asarray(fitted.pop("pattern_index_", np.arange(P.shape[0])), dtype=np.int64)
        model.pattern_set_ = PatternSet(P, Y, counts, index)
        model.bandwidth_ = Bandwidth(
            float(sigma),
            str(fitted.pop("sigma_rule_", "fixed")),
            float(fitted.pop("loo_error_", math.nan)),
            int(fitted.pop("exclude_neighbours_", 0)),
        )
        model.thinning_ = dict(fitted.pop("thinning_", {"rule": "none"}))
        if fitted:
            raise ConfigError(f"unknown fitted attribute(s): {', '.join(sorted(fitted))}")
        model._y1d = False
        return model
