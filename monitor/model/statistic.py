"""The statistics the alarm compares with their thresholds: one interface, one registry.

J (the paper's windowed mean squared residual, eq. 9), B (bias), L (full lever) and H (hold)
are members of one family, as python-can's buses are of ``BusABC``.  A member does only its
own maths: a series over a whole recording's residuals, a window kept up to date one tick at
a time (one kernel serves both), the scales it learns from held-out normal data and what it
keeps in the model file.  The base class does the shared work: the threshold from held-out
normal values (``ThresholdRule``, the rule that sets eps0 from J), the ratio value /
threshold, the alarm level (the largest ratio, 1 = alarm), the summary entries, the model
file's header round trip and its checks.

A member registered with :func:`register` is carried by the ticker, ``monitor detect``, its
summary and plot, the model file, ``monitor train``, eval-sim and the fleet, with no other
change.  scikit-learn's convention: ``__init__`` stores the settings, :meth:`Statistic.fit`
validates held-out data and sets ``params_`` (what the model file keeps) and ``support_``
(what the threshold rests on); :meth:`Statistic.use` sets ``params_`` from a model file.
"""

from __future__ import annotations

import dataclasses
import importlib
import math
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar, Protocol

import numpy as np

from monitor.io.recording import Recording
from monitor.model.filecheck import MAX_WINDOW_N, check_number, check_whole
from monitor.model.support import implied_rate, spool_shares, window_maxima
from monitor.model.threshold import ThresholdRule

#: The members shipped with the monitor, imported (and so registered) before any is used.
BUILTIN = (
    "monitor.model.residual",
    "monitor.model.bias",
    "monitor.model.lever",
    "monitor.model.hold",
    "monitor.model.flow",
)
_REGISTRY: dict[str, type[Statistic]] = {}


class Window(Protocol):
    """A statistic kept up to date one 100 Hz row at a time, allocating nothing per tick (a
    member with ``Statistic.beyond_oil`` has ``step_beyond(e, row, beyond_c)`` besides)."""

    def step(self, e: np.ndarray, row: np.ndarray) -> float:
        """One row's residuals ``e`` (z-units, outputs) and sampler row ``[t, *columns]``;
        the statistic's value (NaN: not judged at this row)."""
        ...


@dataclass(frozen=True)
class HeldOut:
    """Held-out normal data a statistic's scales and threshold are fitted on."""

    residuals: Sequence[np.ndarray]  # e per part (samples, outputs), z-units, NaN where gated
    recordings: Sequence[Recording]  # the same parts' signals
    outputs: tuple[str, ...]  # the model's outputs, the columns of ``residuals``
    #: Every normal recording given to training (geometry such as end stops, not thresholds).
    every: Sequence[Recording] = field(default_factory=tuple)
    validation: str = "held out"  # or "cross-fitted, ..."


def signal(rec: Recording, name: str, default: float) -> np.ndarray:
    """A recording's signal, or ``default`` at every sample when it has none."""
    return rec[name] if rec.has(name) else np.full(len(rec), default)


def column(columns: Sequence[str], name: str) -> int:
    """Index of ``name`` in a sampler row ``[t, *columns]`` (-1: the rows lack it)."""
    return 1 + list(columns).index(name) if name in columns else -1


def largest(x: np.ndarray | None) -> float | None:
    """The largest finite value of a statistic's series (None: none, or never judged)."""
    if x is None or not np.isfinite(x).any():
        return None
    return float(np.nanmax(x))


def raise_level(level: float, value: float, threshold: float) -> float:
    """The alarm level with one more statistic: max(level, value / threshold) where none of
    the three is NaN, else ``level`` unchanged (one tick of :func:`level_series`)."""
    if level == level and value == value and threshold == threshold:  # none is NaN
        return max(level, value / threshold)
    return level


def level_series(
    pairs: Sequence[tuple[np.ndarray, float]],
    beyond: np.ndarray | None = None,
    wide: Sequence[bool] = (),
) -> np.ndarray:
    """What the alarm compares with 1: the first pair's ratio (J / eps0) raised to each
    other's value / threshold where both are finite; NaN while the first is (its window
    warms up or pauses), except where ``beyond`` (per sample: the envelope gated it for its
    OilTemp alone) a member that judges there (``wide``, one flag per pair:
    ``Statistic.beyond_oil``) has a finite ratio: the largest such ratio.  A NaN threshold
    never alarms."""
    return _raise(pairs, beyond, wide)[0]


def naming_series(
    pairs: Sequence[tuple[np.ndarray, float]],
    names: Sequence[str],
    beyond: np.ndarray | None = None,
    wide: Sequence[bool] = (),
) -> np.ndarray:
    """Per sample, the fault named by the member whose ratio sets the level (``names``, one
    per pair, "" for a member that names none), as :func:`level_series` raises it: a later
    member takes over only where its ratio is finite and above the level so far (or where
    the level is NaN beyond the envelope and the member judges there)."""
    return _raise(pairs, beyond, wide, names)[1]


def _raise(
    pairs: Sequence[tuple[np.ndarray, float]],
    beyond: np.ndarray | None,
    wide: Sequence[bool],
    names: Sequence[str] = (),
) -> tuple[np.ndarray, np.ndarray]:
    first, threshold = pairs[0]
    level = np.asarray(first, dtype=np.float64) / threshold
    out = np.full(level.shape, names[0] if names else "", dtype=object)
    past = np.zeros(level.shape, dtype=bool) if beyond is None else np.asarray(beyond, bool)
    flags = list(wide) or [False] * len(pairs)
    with np.errstate(invalid="ignore"):
        for k in range(1, len(pairs)):
            series, thr = pairs[k]
            if thr != thr:
                continue
            ratio = np.asarray(series, dtype=np.float64) / thr
            finite = np.isfinite(ratio)
            both = np.isfinite(level) & finite
            alone = past & ~np.isfinite(level) & finite if flags[k] else np.zeros_like(both)
            if names:
                out[(both & (ratio > level)) | alone] = names[k]
            level = np.where(both, np.maximum(level, ratio), np.where(alone, ratio, level))
    return level, out


def register(cls: type[Statistic]) -> type[Statistic]:
    """Add a member to the family (a class decorator); a name registered again is replaced."""
    _REGISTRY[cls.name] = cls
    return cls


def unregister(name: str) -> None:
    """Remove a member (tests that register their own)."""
    _REGISTRY.pop(name, None)


def registry() -> tuple[type[Statistic], ...]:
    """Every member: J first (not ``optional``: the level rests on it), then by ``order``
    and registration."""
    for module in BUILTIN:
        importlib.import_module(module)
    names = list(_REGISTRY)
    return tuple(
        sorted(_REGISTRY.values(), key=lambda c: (c.optional, c.order, names.index(c.name)))
    )


def active(model: Any) -> list[Statistic]:
    """The members a model carries, each ready to judge (``params_`` from the model)."""
    out = []
    for cls in registry():
        params = cls.get(model)
        if params is not None:
            out.append(cls().use(params))
    return out


class Statistic(ABC):
    """One statistic beside (or as) J: its window, its series, its scales and threshold."""

    name: ClassVar[str]  # the letter in summaries and plots: "B"
    key: ClassVar[str]  # model-file header section, model attribute, training note: "bias"
    threshold_key: ClassVar[str]  # the threshold's name in the header: "b0"
    title: ClassVar[str]  # for people: "bias statistic"
    colour: ClassVar[str] = "tab:grey"  # its line in the detection plot
    unit: ClassVar[str] = ""  # of its threshold, after the number (" z^2")
    order: ClassVar[int] = 100  # place among the members (J 0, B 1, L 2, H 3)
    #: A reference model's threshold floors this one's (a standard score, or J: a model
    #: fitted on minutes predicts no better than one fitted on hours).
    carries_over: ClassVar[bool] = False
    #: Training may leave it out when the held-out data cannot support it (J: never).
    optional: ClassVar[bool] = True
    #: The training switch that asks for it by name ("hold": --hold on): off, it is said.
    asked_by: ClassVar[str] = ""
    #: Whole numbers of samples in its header section, checked 1..MAX_WINDOW_N.
    counts: ClassVar[tuple[str, ...]] = ("window_n",)
    #: The fault an alarm names while this statistic sets the level ("": the isolation's
    #: residual signatures name it): a statistic that only one fault moves.
    names: ClassVar[str] = ""
    #: Its values do not rest on the DGRNN's residuals: it is fitted on every normal
    #: recording given to training (``HeldOut.every``) and holds out its own data.
    own_held_out: ClassVar[bool] = False
    #: Held-out sessions and independent windows its threshold needs (0: the training's
    #: rule, ``monitor.training.support``).
    min_sessions: ClassVar[int] = 0
    min_windows: ClassVar[int] = 0
    #: It judges samples the model's envelope gates for their OilTemp alone, on an oil
    #: range of its own (:meth:`series_beyond`; its window's ``step_beyond``); there, where
    #: J is not judged, it sets the level alone.  False: it judges where J does.
    beyond_oil: ClassVar[bool] = False
    params_: Any

    # -- a member's own maths ------------------------------------------------------------
    @abstractmethod
    def series(self, e: np.ndarray, rec: Recording) -> np.ndarray:
        """The statistic at every sample of a recording's residuals (samples, outputs)."""

    def series_beyond(
        self, e: np.ndarray, rec: Recording, beyond_c: np.ndarray | None
    ) -> np.ndarray:
        """The series as the detector takes it: ``beyond_c`` per sample the OilTemp (degC)
        where the envelope gated the sample for it alone, NaN elsewhere; a member that
        judges there (``beyond_oil``) uses it, the others are :meth:`series`."""
        return self.series(e, rec)

    @abstractmethod
    def window(self, columns: Sequence[str], n_out: int) -> Window:
        """The live form over sampler rows ``[t, *columns]`` and residuals of ``n_out``
        outputs: the same kernel as ``series``, nothing allocated per push."""

    @abstractmethod
    def unscaled(self, held: HeldOut) -> Any:
        """``params_`` with the scales learnt from held-out data, its threshold NaN
        (``InputFileError`` when the data cannot support the statistic)."""

    @classmethod
    @abstractmethod
    def from_dict(cls, d: dict[str, Any]) -> Any:
        """The header section back into ``params_``."""

    # -- training ------------------------------------------------------------------------
    @classmethod
    def configure(cls, settings: Any, outputs: tuple[str, ...], on: set[str]) -> Statistic | str:
        """The member as ``monitor train``'s settings ask for it, or why it is off (``on``:
        the names of the members fitted so far).  Default: on, with its own defaults."""
        return cls()

    def fit(self, held: HeldOut, rule: ThresholdRule) -> Statistic:
        """Scales from ``held`` (the member's), then the threshold from the statistic's
        held-out series by ``rule``, one window per block; sets ``params_`` and ``support_``."""
        if not held.residuals or len(held.residuals) != len(held.recordings):
            raise ValueError("held-out residuals and recordings must pair up, one per part")
        self.params_ = self.unscaled(held)
        parts = [self.series(e, r) for e, r in zip(held.residuals, held.recordings, strict=True)]
        reference, threshold = rule.eps0(np.concatenate(parts), block=self.window_n)
        self.params_ = self.with_threshold(threshold, reference)
        self.support_ = self.support(held, parts)
        return self

    def with_threshold(self, threshold: float, reference: float | None = None) -> Any:
        """``params_`` with this threshold (``reference``: the held-out value it came from,
        None: as it was)."""
        return dataclasses.replace(self.params_, **{self.threshold_key: threshold})

    def support(self, held: HeldOut, parts: Sequence[np.ndarray]) -> dict[str, Any]:
        """What the threshold rests on: hours of judged held-out data, how many of the
        statistic's own windows judged it and how many of them count as independent, the
        false-alarm rate the threshold implies on them with its 95 % bound
        (``monitor.model.support``), the oil temperatures and spool regimes covered, and the
        member's own coverage (:meth:`coverage`)."""
        hours = 0.0
        temps: list[np.ndarray] = []
        for rec, s in zip(held.recordings, parts, strict=True):
            judged = np.isfinite(s)
            period = float(np.median(np.diff(rec.t))) if len(rec) > 1 else 0.01
            hours += float(judged.sum()) * period / 3600.0
            if rec.has("OilTemp"):
                temps.append(rec["OilTemp"][judged & np.isfinite(rec["OilTemp"])])
        maxima = [window_maxima(s, self.window_n) for s in parts]
        oil = np.concatenate(temps) if temps else np.zeros(0)
        out: dict[str, Any] = {
            "validation": held.validation,
            "parts": len(parts),
            "judged_h": round(hours, 4),
            "windows": int(sum(np.isfinite(m).sum() for m in maxima)),
            "window_s": round(self.window_n * 0.01, 3),
        }
        out |= implied_rate(maxima, self.threshold_, self.window_n * 0.01)
        if oil.size:
            out["oil_temp_c"] = [round(float(oil.min()), 2), round(float(oil.max()), 2)]
        if all(r.has("SpoolCmd") for r in held.recordings):
            shares = spool_shares(
                [r["SpoolCmd"] for r in held.recordings], [np.isfinite(s) for s in parts]
            )
            out["spool_share"] = shares
        return out | self.coverage(held)

    def coverage(self, held: HeldOut) -> dict[str, Any]:
        """The member's own coverage of the held-out data (regimes, directions, holds)."""
        return {}

    @classmethod
    def warm(cls) -> None:
        """Its kernels once on a tiny example, so that numba types them before a model that
        carries it is first used (``monitor warm-up``); nothing for a member whose kernels
        every model's ticks reach anyway."""
        return None

    # -- the fitted statistic ------------------------------------------------------------
    def use(self, params: Any) -> Statistic:
        """This member judging with ``params`` (from a model file); returns self."""
        self.params_ = params
        return self

    @property
    def threshold_(self) -> float:
        return float(getattr(self.params_, self.threshold_key))

    @property
    def window_n(self) -> int:
        """Samples in the statistic's window: one block of its threshold's fit."""
        return int(self.params_.window_n)

    @classmethod
    def summary_keys(cls) -> tuple[str, str]:
        """Its keys in ``monitor detect``'s summary: the largest value, the threshold."""
        return f"max_{cls.name}", f"{cls.key}_threshold"

    def summary(self, series: np.ndarray | None) -> dict[str, Any]:
        """``monitor detect``'s summary keys: the largest value and the threshold."""
        top, threshold = self.summary_keys()
        return {top: largest(series), threshold: self.threshold_}

    @classmethod
    def peak_ratio(cls, summary: dict[str, Any]) -> float | None:
        """Its largest value over its threshold, read from a summary (None: the model has
        no such statistic, its window was never judged, or its threshold never alarms)."""
        top, threshold = cls.summary_keys()
        value, limit = summary.get(top), summary.get(threshold)
        return None if value is None or not limit else value / limit

    @classmethod
    def absent(cls) -> dict[str, Any]:
        """The summary keys of a model without this member."""
        return dict.fromkeys(cls.summary_keys())

    # -- the model and its file ----------------------------------------------------------
    @classmethod
    def get(cls, model: Any) -> Any:
        """The member's ``params_`` in a model (None: the model does not carry it)."""
        if cls.key in getattr(type(model), "__dataclass_fields__", {}):
            return getattr(model, cls.key)
        return model.statistics.get(cls.key)

    @classmethod
    def put(cls, model: Any, params: Any) -> None:
        if cls.key in getattr(type(model), "__dataclass_fields__", {}):
            setattr(model, cls.key, params)
        elif params is None:
            model.statistics.pop(cls.key, None)
        else:
            model.statistics[cls.key] = params

    @classmethod
    def write(cls, header: dict[str, Any], params: Any) -> None:
        """Into the model file's header (a section of its own)."""
        header[cls.key] = params.to_dict()

    @classmethod
    def read(cls, header: dict[str, Any], n_out: int) -> Any:
        """From a checked header (None: the file has no such section)."""
        if header.get(cls.key) is None:
            return None
        params = cls.from_dict(header[cls.key])
        cls.check_outputs(params, n_out)
        return params

    @classmethod
    def check_outputs(cls, params: Any, n_out: int) -> None:
        """ValueError when ``params`` name outputs the model does not have."""
        return None

    @classmethod
    def check_header(cls, header: dict[str, Any]) -> None:
        """Types and ranges of the member's header section (ValueError): its window and
        ``counts``, a finite positive threshold, and what :meth:`check_more` adds."""
        stat = header.get(cls.key)
        if stat is None:
            return
        if not isinstance(stat, dict):
            raise ValueError(f"header {cls.key} must be an object")
        for key in cls.counts:
            check_whole(stat, key, 1, MAX_WINDOW_N, f"{cls.key}.")
        check_number(stat, cls.threshold_key, 0.0, strict=True)
        cls.check_more(stat)

    @classmethod
    def check_more(cls, section: dict[str, Any]) -> None:
        """The member's own header keys beyond window, count and threshold."""
        return None

    # -- what a summary says about it ----------------------------------------------------
    @classmethod
    def entry(cls, model: Any) -> dict[str, Any]:
        """The summary's ``statistics`` entry: on (it can raise an alarm), its threshold,
        why (the training's note), and what held-out data the threshold rests on."""
        params = cls.get(model)
        training = model.training if isinstance(model.training, dict) else {}
        note = training.get(cls.key)
        if params is None:
            why = note if isinstance(note, str) else "off: not in this model file"
            return {"on": False, "threshold": None, "why": why, "support": {}}
        threshold = cls().use(params).threshold_
        on = math.isfinite(threshold)
        why = (
            (note if isinstance(note, str) else "on")
            if on
            else "off: no threshold (computed, never alarms)"
        )
        return {
            "on": on,
            "threshold": threshold if on else None,
            "why": why,
            "support": cls.known_support(training),
        }

    @classmethod
    def known_support(cls, training: dict[str, Any]) -> dict[str, Any]:
        """What the model file knows of the held-out data the threshold rests on: how it
        was held out, how many parts, the rule, what training recorded for this statistic
        (``support``: hours, windows, oil temperatures, its coverage) when it did, and a
        reference model's floor when that set the threshold."""
        out: dict[str, Any] = {}
        if isinstance(training.get("validation"), str):
            out["validation"] = training["validation"]
        if isinstance(training.get("validation_from"), list):
            out["parts"] = len(training["validation_from"])
        if isinstance(training.get("threshold"), str):
            out["rule"] = training["threshold"]
        recorded = training.get("support")
        if isinstance(recorded, dict) and isinstance(recorded.get(cls.name), dict):
            out |= recorded[cls.name]
        floor = training.get("threshold_floor")
        if isinstance(floor, str) and f"{cls.threshold_key} " in floor:
            out["floor"] = floor
        return out


def statistic_keys(model: Any, series: dict[str, np.ndarray]) -> dict[str, Any]:
    """``monitor detect``'s summary keys of every member: its largest value and threshold
    (``max_J``, ``threshold``, ``J0``, ``max_B``, ``bias_threshold``, ...; null without it)."""
    out: dict[str, Any] = {}
    for cls in registry():
        params = cls.get(model)
        out |= cls.absent() if params is None else cls().use(params).summary(series.get(cls.name))
    return out


def statistics_entries(model: Any) -> dict[str, dict[str, Any]]:
    """The summary's ``statistics``: every member by name, whether it was on and why."""
    return {cls.name: cls.entry(model) for cls in registry()}
