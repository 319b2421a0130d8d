"""What a DGRNN is, without computing one: its spec (variables, lags, outputs), the presets,
the z-score normaliser of the F0 data, and tables of signals.  Light to import (numpy only),
so that command lines and configuration can name presets without loading the kernels.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from monitor.errors import ConfigError, InputFileError
from monitor.signals import ROD_SPEED, contract_name


@dataclass(frozen=True)
class DGRNNSpec:
    """Which signals are predicted, from which lagged inputs, over which horizon.

    ``lags`` maps variable name -> lags in samples, as a tuple of pairs so the spec stays
    hashable, e.g. ``(("QP", (1, 2)), ("PP", (1, 2)))``.  Outputs need lags >= 1 (their
    value at t is what is predicted); exogenous inputs may use lag 0 (the measured value at
    t, e.g. the command issued this tick).
    """

    outputs: tuple[str, ...]
    exogenous: tuple[str, ...]
    lags: tuple[tuple[str, tuple[int, ...]], ...]
    horizon: int = 1
    #: Outputs predicted as a change from the previous sample instead of a level:
    #: y_hat(t) = y(t-1) + GRNN(x(t)).  A GRNN only averages its training targets and cannot
    #: extrapolate, so a level model fails on every trapped-pressure level the training runs
    #: missed; increments are near zero at any held level.  Each needs its lag 1.  ``True``
    #: means every output, ``False`` none.
    delta: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        lags = tuple(self.lags.items()) if isinstance(self.lags, Mapping) else tuple(self.lags)
        norm = tuple((str(name), tuple(int(v) for v in ls)) for name, ls in lags)
        object.__setattr__(self, "outputs", tuple(self.outputs))
        object.__setattr__(self, "exogenous", tuple(self.exogenous))
        object.__setattr__(self, "lags", norm)
        object.__setattr__(self, "horizon", int(self.horizon))
        if isinstance(self.delta, bool):
            object.__setattr__(self, "delta", self.outputs if self.delta else ())
        object.__setattr__(self, "delta", tuple(str(n) for n in self.delta))
        self._validate()

    def _validate(self) -> None:
        if not self.outputs:
            raise ConfigError("a DGRNN needs at least one output")
        variables = self.variables
        # A model file's spec may hold anything JSON holds; a name is a non-empty string.
        odd = [v for v in variables if not isinstance(v, str) or not v]
        if odd:
            raise ConfigError(f"outputs and exogenous inputs must be signal names, got {odd!r}")
        if len(set(variables)) != len(variables):
            raise ConfigError(f"a variable is listed twice in outputs/exogenous: {variables}")
        names = [name for name, _ in self.lags]
        if len(set(names)) != len(names):
            raise ConfigError("a variable appears twice in lags")
        for name, ls in self.lags:
            if name not in variables:
                raise ConfigError(f"lag variable {name!r} is neither an output nor exogenous")
            if not ls or len(set(ls)) != len(ls):
                raise ConfigError(f"lags of {name!r} must be non-empty and distinct")
            least = 1 if name in self.outputs else 0
            if min(ls) < least:
                raise ConfigError(
                    f"lags of {name!r} must be >= {least}"
                    + (" (an output at lag 0 is the value being predicted)" if least else "")
                )
        if not self.lags:
            raise ConfigError("a DGRNN needs at least one lagged input")
        if self.horizon < 1:
            raise ConfigError(f"horizon must be >= 1, got {self.horizon}")
        if self.delta:
            lagmap = dict(self.lags)
            strangers = [o for o in self.delta if o not in self.outputs]
            if strangers:
                raise ConfigError(f"delta targets must be outputs: {strangers}")
            lacking = [o for o in self.delta if 1 not in lagmap.get(o, ())]
            if lacking:
                raise ConfigError(f"delta targets need lag 1 of each such output: {lacking}")

    @property
    def variables(self) -> tuple[str, ...]:
        """Column order of the data arrays: outputs, then exogenous inputs."""
        return (*self.outputs, *self.exogenous)

    @property
    def features(self) -> tuple[tuple[str, int], ...]:
        """(variable, lag) of every input feature, lag-major as in eq. 11."""
        all_lags = sorted({lag for _, ls in self.lags for lag in ls})
        return tuple((name, lag) for lag in all_lags for name, ls in self.lags if lag in ls)

    @property
    def max_lag(self) -> int:
        return max(lag for _, ls in self.lags for lag in ls)

    def rows_needed(self, horizon: int | None = None) -> int:
        """Rows of history (ending with the current sample) that one prediction reads."""
        p = self.horizon if horizon is None else int(horizon)
        return p + self.max_lag

    def delta_mask(self) -> np.ndarray:
        """1 for each output predicted as an increment, 0 for a level (kernel argument)."""
        return np.array([1 if o in self.delta else 0 for o in self.outputs], dtype=np.int64)

    def feature_columns(self) -> tuple[np.ndarray, np.ndarray]:
        """(column index into ``variables``, lag) per feature, as int64 arrays for numba."""
        col = {name: i for i, name in enumerate(self.variables)}
        feats = self.features
        return (
            np.array([col[n] for n, _ in feats], dtype=np.int64),
            np.array([lag for _, lag in feats], dtype=np.int64),
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "outputs": list(self.outputs),
            "exogenous": list(self.exogenous),
            # A list of pairs, not a mapping: the order fixes the feature columns, and JSON
            # writers may sort mapping keys.
            "lags": [[name, list(ls)] for name, ls in self.lags],
            "horizon": self.horizon,
            "delta": list(self.delta),
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> DGRNNSpec:
        try:
            lags = d["lags"]
            pairs = tuple(lags.items()) if isinstance(lags, Mapping) else tuple(map(tuple, lags))
            delta = d.get("delta", ())
            if isinstance(delta, bool):  # True: every output, as the constructor reads it
                delta = tuple(d["outputs"]) if delta else ()
            return cls(d["outputs"], d["exogenous"], pairs, d["horizon"], tuple(delta))
        except (KeyError, AttributeError, TypeError) as exc:
            shown = repr(dict(d))  # cut: a model file's spec may be anything
            shown = shown if len(shown) <= 80 else shown[:77] + "..."
            raise ConfigError(f"bad DGRNN spec {shown}: {exc}") from None

    @classmethod
    def preset(
        cls,
        name: str,
        horizon: int | None = None,
        neighbours: Sequence[str] = (),
        rod_speed: bool = False,
    ) -> DGRNNSpec:
        """Preset ``name``; ``neighbours``: the other loops' demand columns a ``section``
        model takes as inputs (``SpoolCmd@LOOP``, ``monitor.signals.neighbour``);
        ``rod_speed``: a ``section`` model predicts the rod's speed too (``section_spec``)."""
        try:
            spec = PRESETS[name]
        except KeyError:
            raise ConfigError(
                f"unknown preset {name!r}; choose one of {', '.join(PRESETS)}"
            ) from None
        if name == "section":
            spec = section_spec(neighbours, rod_speed)
        elif rod_speed:
            raise ConfigError(f"the rod speed is an output of the section preset, not {name!r}")
        if horizon is None:
            return spec
        return cls(spec.outputs, spec.exogenous, spec.lags, horizon, spec.delta)


def section_spec(neighbours: Sequence[str] = (), rod_speed: bool = False) -> DGRNNSpec:
    """A section of a load-sensing valve on a pump it shares with ``neighbours`` (their
    spool commands): PA, PB and the section's flow QP predicted; PP an input.  The pump
    sets PP at the highest load pressure of every open section plus its margin, so PP is
    the neighbours' doing as much as this section's, and predicting it from this section's
    signals would read a neighbour's load as a fault here.  Given PP (at t and t-1), a
    post-compensated section's flow is its opening times the common drop, the same whatever
    its load, until the pump saturates: then every section's flow shrinks by the pump's
    flow over the total demand, which the neighbours' commands at t say.

    ``rod_speed``: RodSpeed (``monitor.signals.ROD_SPEED``, from RodPos) is a fourth output,
    predicted from the section's flow and pressures at their lags, never from its own past
    (which would carry a slow rod over as normal): a piston leak passes part of the flow
    across the piston, so the rod moves slower for the same flow and drop."""
    return DGRNNSpec(
        outputs=("PA", "PB", "QP", *((ROD_SPEED.name,) if rod_speed else ())),
        exogenous=("PP", "SpoolCmd", "EngineSpeed", "OilTemp", *neighbours),
        lags=(
            ("PA", (1, 2)),
            ("PB", (1, 2)),
            ("QP", (1, 2)),
            ("PP", (0, 1)),
            ("SpoolCmd", (0, 1)),
            ("EngineSpeed", (0,)),
            ("OilTemp", (0,)),
            *((n, (0,)) for n in neighbours),
        ),
        delta=("PA", "PB"),
    )


PRESETS: dict[str, DGRNNSpec] = {
    # Eq. 11 exactly: QP(t) from QP, PP, PA, PB at t-1 and t-2.  PP, PA, PB are measured
    # inputs, so they are exogenous: multi-step prediction feeds back only QP.
    "paper": DGRNNSpec(
        outputs=("QP",),
        exogenous=("PP", "PA", "PB"),
        lags=(("QP", (1, 2)), ("PP", (1, 2)), ("PA", (1, 2)), ("PB", (1, 2))),
    ),
    # All four measured signals predicted by one kernel pass.  Two lags of PA, PB and QP
    # give a level and a rate (what a second-order loop needs); the spool command at t
    # and t-1 gives the opening now and its rate (the nominal spool follows the command
    # instantly, so the current command drives the current flows); the pump command, engine
    # speed and oil temperature change slowly, so their current value is enough.  PA and PB
    # are predicted as increments (``delta``): trapped at a held spool, their level depends
    # on history, and a level no training run visited is then still predicted to hold.  PP
    # and QP keep level targets: the pump sets them (compensator, displacement x speed) and
    # the valve opening, so their level is predictable, and a fault that shifts it (a
    # stroke-limited spool raising PP) stays visible after the transient.  PP has no lags
    # of its own: the 0.5 L pump line settles within milliseconds, so PP is near-algebraic
    # in the flows and the opening at 100 Hz, and its own past would only let the model
    # copy a faulty level instead of checking it.
    "default": DGRNNSpec(
        outputs=("PP", "PA", "PB", "QP"),
        exogenous=("SpoolCmd", "PumpDispCmd", "EngineSpeed", "OilTemp"),
        lags=(
            ("PA", (1, 2)),
            ("PB", (1, 2)),
            ("QP", (1, 2)),
            ("SpoolCmd", (0, 1)),
            ("PumpDispCmd", (0,)),
            ("EngineSpeed", (0,)),
            ("OilTemp", (0,)),
        ),
        delta=("PA", "PB"),
    ),
    # One section of a load-sensing machine (``section_spec``): PP an input; `monitor train
    # --loop` adds the other loops' spool commands.
    "section": section_spec(),
}


# --------------------------------------------------------------------------- normalisation

#: Floors for the standard deviation (physical units).  A signal that is (nearly) constant in
#: the F0 data, such as EngineSpeed at a fixed 2200 rpm, would otherwise be divided by ~0 and
#: turn sensor noise into huge z-scores that dominate every distance.  Real signals have
#: standard deviations far above these floors, where the scaling is the paper's z-score.
#: OilTemp is the exception that matters: it is nearly constant within a run and differs by
#: a few degrees between runs, so its F0 std (a few degC) would make a 5 degC difference
#: as far apart as a change of operating point, and split the patterns into one island per
#: run.  Its floor of 15 degC says what matters physically: viscosity moves visibly over
#: tens of degrees, not over two or three.
DEFAULT_MIN_STD: dict[str, float] = {
    "PP": 1.0,
    "PA": 1.0,
    "PB": 1.0,
    "QP": 0.5,
    "SpoolCmd": 1.0,
    "PumpDispCmd": 1.0,
    "EngineSpeed": 10.0,
    "OilTemp": 15.0,
    # Far above the rod speed's own spread (some 50 mm/s): J averages the outputs' squared
    # z residuals, and RodPos's 0.5 mm scatter (7 mm/s on the speed) would outweigh the
    # pressures' and the flow's.  The GRNN's average and L's own scales do not depend on it.
    "RodSpeed": 500.0,
}


class Normalizer:
    """Z-score with the mean and standard deviation (ddof=1, as Matlab) of F0 data."""

    def __init__(self, min_std: Mapping[str, float] | None = None) -> None:
        self.min_std = dict(DEFAULT_MIN_STD if min_std is None else min_std)

    def fit(self, data: Any, names: Sequence[str]) -> Normalizer:
        """Statistics per column of ``data`` (rows x len(names)), NaN (missing) ignored."""
        A = _table(data, names)
        names = tuple(names)
        counts = np.sum(~np.isnan(A), axis=0)
        for name, c in zip(names, counts, strict=True):
            if c < 2:
                raise InputFileError(f"signal {name!r} has fewer than 2 valid samples to scale")
        mean = np.nanmean(A, axis=0)
        std = np.nanstd(A, axis=0, ddof=1)
        # Another loop's signal (``SpoolCmd@stick``) has its signal's floor.
        floor = np.array([self.min_std.get(contract_name(n), 0.0) for n in names])
        std = np.maximum(std, floor)
        for name, s in zip(names, std, strict=True):
            if not s > 0:
                raise ConfigError(
                    f"signal {name!r} is constant in the normal data; give it a min_std floor"
                )
        self.names_, self.mean_, self.std_ = names, mean, std
        return self

    def _cols(self, names: Sequence[str] | None) -> np.ndarray:
        if not hasattr(self, "names_"):
            raise ConfigError("this Normalizer is not fitted yet: call fit(data, names) first")
        if names is None:
            return np.arange(len(self.names_))
        missing = [n for n in names if n not in self.names_]
        if missing:
            raise ConfigError(f"the normaliser has no statistics for {', '.join(missing)}")
        return np.array([self.names_.index(n) for n in names], dtype=np.int64)

    def transform(self, data: Any, names: Sequence[str] | None = None) -> np.ndarray:
        """(x - mean) / std, columns named by ``names`` (default: the fitted order)."""
        c = self._cols(names)
        A = _table(data, [self.names_[i] for i in c])
        return (A - self.mean_[c]) / self.std_[c]

    def inverse_transform(self, z: Any, names: Sequence[str] | None = None) -> np.ndarray:
        c = self._cols(names)
        A = _table(z, [self.names_[i] for i in c])
        return A * self.std_[c] + self.mean_[c]

    def to_dict(self) -> dict[str, Any]:
        self._cols(None)
        return {
            "names": list(self.names_),
            "mean": [float(v) for v in self.mean_],
            "std": [float(v) for v in self.std_],
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Normalizer:
        out = cls()
        out.names_ = tuple(d["names"])
        out.mean_ = np.asarray(d["mean"], dtype=np.float64)
        out.std_ = np.asarray(d["std"], dtype=np.float64)
        if not (out.mean_.shape == out.std_.shape == (len(out.names_),)) or not np.all(
            out.std_ > 0
        ):
            raise ConfigError("normaliser statistics are inconsistent")
        return out


def _table(data: Any, names: Sequence[str]) -> np.ndarray:
    """A (rows, len(names)) float64 array from an array or a Recording-like mapping."""
    if hasattr(data, "columns") or isinstance(data, Mapping):
        return np.column_stack([np.asarray(data[n], dtype=np.float64) for n in names])
    A = np.asarray(data, dtype=np.float64)
    if A.ndim == 1 and len(names) == 1:
        A = A[:, None]
    if A.ndim != 2 or A.shape[1] != len(names):
        raise InputFileError(f"expected {len(names)} columns ({', '.join(names)}), got {A.shape}")
    return A


def table(recording: Any, names: Sequence[str]) -> np.ndarray:
    """Columns ``names`` of a Recording (or mapping) as one (rows, len(names)) array."""
    return _table(recording, names)
