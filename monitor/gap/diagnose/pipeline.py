"""The sim-to-real diagnosis, end to end, as named stages: the recording split into parts,
the tolerances calibrated, every effect fitted, the best refitted, pairs, the verdict, what
to model next, and the whole-recording runs the report shows.

Verdict rules: see ``judge/decide.py``.  The tolerances are calibrated twice: first from
the nominal values, then again from where the joint refits of the best effects put them, so
that an effect is never credited with what a better calibration alone achieves.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

from threadpoolctl import threadpool_limits

from monitor.gap.diagnose import atrest, deadband, identify, slip
from monitor.gap.diagnose import fitting as F
from monitor.gap.diagnose import timing as T
from monitor.gap.diagnose import verdict as V
from monitor.gap.diagnose.records import (
    Diagnosis,
    Finding,
    Parts,
    Ranking,
    Tolerances,
    Traces,
)
from monitor.gap.fit import calibrate as cal_mod
from monitor.gap.fit.candidates import KNOBS
from monitor.gap.fit.predict import predict
from monitor.io.recording import Recording
from monitor.sim.machine import MachineParams

Progress = F.Progress


def diagnose(
    rec: Recording,
    machine: MachineParams,
    progress: Progress | None = None,
    effects: Sequence[str] = tuple(KNOBS),
) -> Diagnosis:
    """Diagnose the gap between ``machine``'s simulator and ``rec``."""
    # The fits' linear algebra works on Jacobians of a few columns: BLAS threads gain
    # nothing there, and OpenBLAS's idle threads spin between calls (with two of them, 6 of
    # 16 CPU seconds of a diagnosis went to spinning).
    with threadpool_limits(limits=1, user_api="blas"):
        return _diagnose(rec, machine, progress or _silent, effects)


def _silent(_msg: str) -> None:
    pass


class _Laps:
    """Wall time per stage (the JSON's ``timings_s``)."""

    def __init__(self) -> None:
        self.start = time.perf_counter()
        self.timings: dict[str, float] = {}

    def lap(self, name: str) -> None:
        self.timings[name] = time.perf_counter() - self.start - sum(self.timings.values())


def _diagnose(
    rec: Recording, machine: MachineParams, say: Progress, effects: Sequence[str]
) -> Diagnosis:
    laps = _Laps()
    parts = F.split_recording(rec, machine, say)
    machine = F.valve_law(parts, machine, say)
    cal = F.calibrate_tolerances(parts, machine, say)
    parts = F.with_prep(parts, cal)
    laps.lap("calibrate")
    singles = F.fit_singles(parts, cal, effects, say)
    laps.lap("candidates")
    refined = F.refine(parts, cal, singles, say)
    laps.lap("refine")
    paired = F.fit_pairs(parts, cal, refined, say)
    laps.lap("pairs")
    judged = V.judge(cal, refined, paired, say)
    judged = V.check_timing(cal, refined, paired, judged, say)
    judged = T.check_split(cal, refined, paired, judged, say)
    judged = deadband.check_metering(parts, cal, refined, paired, judged, say)
    judged = V.check_friction(parts, cal, refined, paired, judged, say)
    judged = atrest.check_load(parts, cal, refined, paired, judged, say)
    judged = atrest.check_air(cal, refined, judged, say)
    judged = V.check_cause(parts, cal, refined, paired, judged, say)
    judged = slip.check_slip(parts, cal, refined, paired, judged, say)
    if judged.cause is not None:
        laps.lap("cause")
    finding = V.suggest_next(parts, cal, refined, paired, judged, say)
    finding = T.check_shared(finding, say)
    if judged.decision.verdict in ("unexplained", V.sensorcal.NAME):
        laps.lap("suggest")
    pairs_apart = identify.measure(cal, refined)
    laps.lap("identify")
    laps.timings["total"] = time.perf_counter() - laps.start
    base = refined.baseline
    tolerances = Tolerances(
        machine=cal_mod.apply(machine, base.factors),
        factors=base.factors,
        floor=cal.floor,
        nominal=base.nominal,
        smooth_nominal=base.smooth_nominal,
    )
    ranking = Ranking(
        singles=refined.singles,
        pairs=paired.pairs,
        sums=paired.sums,
        smooth=paired.smooth,
        boot_idx=paired.boot_idx,
        absorbed=judged.absorbed,
    )
    traces = simulate_traces(parts, tolerances, finding, machine)
    return Diagnosis(
        parts=parts,
        tolerances=tolerances,
        ranking=ranking,
        finding=finding,
        traces=traces,
        timings_s=laps.timings,
        identifiability=pairs_apart,
        metering_check=judged.metering,
    )


def simulate_traces(
    parts: Parts, tolerances: Tolerances, finding: Finding, machine: MachineParams
) -> Traces:
    """Stage 8: the whole recording simulated at the configured step, calibrated nominal and
    (when an effect is named) corrected: what the report's plots and regimes show."""
    prep, segs = parts.prep, parts.segments
    nominal = predict(prep, segs, tolerances.machine, ())
    corrected = None
    chosen = finding.chosen
    if chosen is not None:
        m = cal_mod.apply(machine, chosen.factors)
        # Started from the rod path the hypothesis reads (``reread.py``), if its own.
        own = chosen.prep if chosen.prep is not None else prep
        corrected = predict(own, segs, m, chosen.effects)
    return Traces(nominal=nominal, corrected=corrected)
