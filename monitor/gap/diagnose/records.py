"""The diagnosis's records: what each stage hands the next, and the ``Diagnosis`` the
report renders.  Frozen: a stage builds a new record, never changes the one it was given."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from monitor.gap.data.prepare import Prepared
from monitor.gap.data.segments import Segment
from monitor.gap.diagnose.evaluate import Readings, Sums
from monitor.gap.fit import score as S
from monitor.gap.fit.candidates import Candidate
from monitor.sim.machine import MachineParams


@dataclass(frozen=True)
class Parts:
    """The recording as read, cut into segments and split into calibration and held-out
    parts (``fitted``: the calibration segments the fits simulate)."""

    prep: Prepared
    segments: list[Segment]
    calibration: list[Segment]
    heldout: list[Segment]
    fitted: list[Segment]


@dataclass(frozen=True)
class Baseline:
    """The tolerance-calibrated simulator on the held-out part: what an effect must beat."""

    #: The tolerance fit (its ``fit_cost`` is what a recalibration must beat).
    cal: Candidate
    factors: dict[str, float]
    #: The held-out run (the suggestion starts from it: ``suggest``'s ``held_base``).
    pred0: dict
    nominal: S.SegmentSums
    smooth_nominal: S.SegmentSums
    gap0: float
    n_eff: float


@dataclass(frozen=True)
class Calibrated:
    """The tolerances calibrated: the recording as every candidate reads it (without RodPos,
    less the arrivals a first QP calibration finds), its evaluators, the noise floor."""

    prep: Prepared
    readings: Readings
    baseline: Baseline
    floor: np.ndarray
    #: The machines the fits and the held-out scores simulate (their RK4 steps).
    fit_machine: MachineParams
    held_machine: MachineParams


@dataclass(frozen=True)
class Scores:
    """Candidates ranked best first, with their held-out sums (whole and smoothed) by name."""

    singles: list[Candidate]
    sums: dict[str, S.SegmentSums]
    smooth: dict[str, S.SegmentSums]
    #: The baseline the candidates were scored against (a recalibration replaces it).
    baseline: Baseline


@dataclass(frozen=True)
class Paired:
    """The pairs tried, the bootstrap resamples of the held-out segments, and the sums of
    singles and pairs together."""

    pairs: list[Candidate]
    boot_idx: np.ndarray
    sums: dict[str, S.SegmentSums]
    smooth: dict[str, S.SegmentSums]


@dataclass(frozen=True)
class Absorbed:
    """A calibration that took a tolerance an effect trades off against to its bound, where
    the effect's own fit moved it off: the bound stood in for the effect (``decide.py``)."""

    #: Per tolerance: its factor in the calibration and in the effect's fit.
    tolerances: dict[str, tuple[float, float]]
    #: Held-out whole and smoothed sums of the effect's tolerances without the effect.
    sums: Sums


@dataclass(frozen=True)
class Traces:
    """Whole-recording simulations for the report: calibrated nominal and corrected."""

    nominal: dict[str, np.ndarray]
    corrected: dict[str, np.ndarray] | None


@dataclass(frozen=True)
class Tolerances:
    """The tolerance calibration as the report shows it."""

    machine: MachineParams  # tolerance-calibrated
    factors: dict[str, float]
    floor: np.ndarray
    nominal: S.SegmentSums  # held-out, calibrated nominal
    # The same, on the smoothed (structured) residual: see ``basemis.py``.
    smooth_nominal: S.SegmentSums | None


@dataclass(frozen=True)
class Ranking:
    """Every candidate tried, scored on the held-out part."""

    singles: list[Candidate]  # ranked best first
    pairs: list[Candidate]
    sums: dict[str, S.SegmentSums]  # held-out per candidate name
    smooth: dict[str, S.SegmentSums]
    boot_idx: np.ndarray
    #: Per candidate name: the calibration absorbed it (``calibration_absorbed``).
    absorbed: dict[str, Absorbed]


@dataclass(frozen=True)
class Finding:
    """The verdict and what was checked on the way to it."""

    verdict: str
    also: str | None
    chosen: Candidate | None
    confidence: float
    #: For ``unexplained``: the terms to model next (``suggest.py``); empty otherwise.
    suggestion: list[dict] = field(default_factory=list)
    suggestion_tried: list[dict] = field(default_factory=list)
    #: A sensor calibration's verdict against the best plant term (``sensorphysics.py``).
    sensor_check: dict | None = None
    #: The best effect, not named because it made a signal clearly worse
    #: (``consistency.py``): the JSON's ``trade_off``.
    traded: dict | None = None
    #: A ``sensor_lag`` verdict checked against the engine's ripple (``lagcheck.py``): the
    #: JSON's ``lag_check``.
    lag_check: dict | None = None
    #: An ``oil_viscosity`` leak checked against the oil temperature (``cause.py``): the
    #: JSON's ``cause_check``.
    cause_check: dict | None = None
    #: A ``sensor_lag`` verdict checked against the rod's timing (``verdict.check_timing``):
    #: the JSON's ``timing_check``.
    timing_check: dict | None = None
    #: The rod's friction read from its force balance (``verdict.check_friction``): the
    #: JSON's ``friction_check``.
    friction_check: dict | None = None
    #: Which readings are late, the delay the others share, and what that decided
    #: (``diagnose/timing.py``): the JSON's ``timing``.
    timing: dict | None = None
    #: The rod's load read at rest (``diagnose/atrest.py``): the JSON's ``load_check``.
    load_check: dict | None = None
    #: The drained chambers' stiffness at rest (``diagnose/atrest.py``): ``air_check``.
    air_check: dict | None = None
    #: A pump leakage against a healthy pump's slip (``diagnose/slip.py``): ``slip_check``.
    slip_check: dict | None = None


@dataclass(frozen=True)
class Diagnosis:
    """Everything the report needs."""

    parts: Parts
    tolerances: Tolerances
    ranking: Ranking
    finding: Finding
    traces: Traces
    timings_s: dict[str, float]
    #: How well the recording separates the look-alike pairs (``identify.py``).
    identifiability: list[dict] = field(default_factory=list)
    #: A deadband told from a progressive metering curve by the held flows
    #: (``diagnose/deadband.py``): the JSON's ``metering_check``.
    metering_check: dict | None = None
