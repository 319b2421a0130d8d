"""Cut a prepared recording into segments, each simulated from its measured start state.

Driven open loop, a simulated cylinder drifts away from the real one, so the comparison
restarts often.  Segments start where the state is known best: a moment after the spool
has come back to centre (rod at rest, trapped pressures measured), or after the rod has
arrived at an end stop (a simulated rod that arrives a little later would otherwise trap
the load pressure the real one has already drained: tens of bar of residual from a
fraction of a second of timing); a stretch without such a moment is cut at fixed lengths
and started from the measured moving state.  Segments are
then split into interleaved blocks: a calibration part (fits) and a held-out part (scores).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monitor.gap.data.prepare import Prepared
from monitor.gap.data.rodflow import CENTRE_PCT
from monitor.signals import SAMPLE_PERIOD_S

#: The spool must have rested this long before a quiet start (s).
QUIET_S = 0.2
#: A rod within this of a stop for STOP_S has arrived there (mm, s).
STOP_MARGIN_MM = 3.0
STOP_S = 0.1
MIN_SEGMENT_S = 2.0
MAX_SEGMENT_S = 12.0
#: Samples right after a start are not scored: the start state is an estimate.
SETTLE_SAMPLES = 5
#: Interleaved blocks: even ones calibrate, odd ones are held out.
N_BLOCKS = 4


@dataclass(frozen=True)
class Segment:
    """Grid rows ``start .. stop`` (inclusive) simulated together; scored from ``score_from``."""

    start: int
    stop: int
    quiet: bool

    @property
    def score_from(self) -> int:
        return self.start + SETTLE_SAMPLES

    @property
    def scored(self) -> slice:
        """Rows this segment scores; consecutive segments share their boundary row only here."""
        return slice(self.score_from, self.stop)

    def duration_s(self) -> float:
        return (self.stop - self.start) * SAMPLE_PERIOD_S


def _run_reaches(mask: np.ndarray, need: int) -> np.ndarray:
    """Rows where a run of true values reaches ``need`` rows (one per run)."""
    run = np.zeros(len(mask), dtype=np.int64)
    count = 0
    for i, c in enumerate(mask):
        count = count + 1 if c else 0
        run[i] = count
    return np.flatnonzero(run == need)


def _quiet_starts(prep: Prepared) -> np.ndarray:
    """Rows where the spool has been centred for QUIET_S, or the rod has sat on an end stop
    for STOP_S (one per resting spell)."""
    rate = 1.0 / SAMPLE_PERIOD_S
    centred = (np.abs(prep.cmd["SpoolCmd"]) < CENTRE_PCT) & prep.valid
    rod = prep.rod_mm
    at_stop = ((rod < STOP_MARGIN_MM) | (rod > prep.stroke_mm - STOP_MARGIN_MM)) & prep.valid
    rows = np.union1d(
        _run_reaches(centred, int(round(QUIET_S * rate))),
        _run_reaches(at_stop, int(round(STOP_S * rate))),
    )
    return rows


def _valid_runs(valid: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) rows of each run of valid samples."""
    edges = np.diff(np.concatenate(([0], valid.astype(np.int8), [0])))
    starts = np.flatnonzero(edges == 1)
    stops = np.flatnonzero(edges == -1) - 1
    return list(zip(starts.tolist(), stops.tolist(), strict=True))


def make_segments(prep: Prepared) -> list[Segment]:
    """Segments covering every valid stretch of the recording, in time order."""
    quiet = set(_quiet_starts(prep).tolist())
    min_len = int(round(MIN_SEGMENT_S / SAMPLE_PERIOD_S))
    max_len = int(round(MAX_SEGMENT_S / SAMPLE_PERIOD_S))
    segments: list[Segment] = []
    for first, last in _valid_runs(prep.valid):
        if last - first < min_len:
            continue
        bounds = [first] + sorted(q for q in quiet if first + min_len <= q <= last - min_len)
        # Drop boundaries that would make a segment shorter than min_len.
        kept = [bounds[0]]
        for b in bounds[1:]:
            if b - kept[-1] >= min_len:
                kept.append(b)
        kept.append(last)
        if kept[-1] - kept[-2] < min_len and len(kept) > 2:
            del kept[-2]
        for a, b in zip(kept[:-1], kept[1:], strict=True):
            n_parts = int(np.ceil((b - a) / max_len))
            cuts = np.linspace(a, b, n_parts + 1).round().astype(int)
            for i, (s, e) in enumerate(zip(cuts[:-1], cuts[1:], strict=True)):
                segments.append(Segment(int(s), int(e), quiet=(i == 0 and int(s) in quiet)))
    return segments


def split(segments: list[Segment]) -> tuple[list[Segment], list[Segment]]:
    """Calibration and held-out segments: interleaved blocks of about equal duration."""
    total = sum(s.duration_s() for s in segments)
    cal: list[Segment] = []
    held: list[Segment] = []
    elapsed = 0.0
    for seg in segments:
        block = min(int(elapsed / total * N_BLOCKS), N_BLOCKS - 1)
        (cal if block % 2 == 0 else held).append(seg)
        elapsed += seg.duration_s()
    return cal, held


def spread(segments: list[Segment], budget_s: float) -> list[Segment]:
    """An evenly spread subset of at most ``budget_s`` seconds (fits run on this)."""
    total = sum(s.duration_s() for s in segments)
    if total <= budget_s:
        return list(segments)
    n = max(1, int(len(segments) * budget_s / total))
    idx = np.unique(np.linspace(0, len(segments) - 1, n).round().astype(int))
    return [segments[i] for i in idx]
