"""How much flow the recording passes at held command levels against what an overlap of the
spool would let through: a deadband's steady signature, where its timing is too short to
read.

An overlap of ``o`` (% stroke) shortens every metering opening: a held command ``A`` opens
the valve ``(A - o) / (1 - o)`` instead of ``A`` (the simulator's law), so where the valve
and not the pump sets the flow, the flow falls short by a share that grows as the command
gets smaller (and a command below the overlap passes nothing).  A delay every reading shares
moves no held flow at all, nor does a slow spool or pump once it has settled.  Where the
spool is ramped fast (the third plant's 900 %/s) a 10 % overlap is crossed in 11 ms, about
one sample: too short to time at the openings and closings (``onsets``), while it takes a
fifth of the flow at a command of 30 %.

Per held command (the spool held ``HOLD_S`` or more out of centre, its first ``SETTLE_S``
left to settle), the recording's mean flow over the calibrated simulator's (``r``) and the
simulator's with a probe overlap (``PROBE_PCT``) over the same (``s``, what it leaves there).
Read are the levels the valve already sets in the simulator (the overlap moves the pump's
pressure by ``PP_MOVED_BAR`` or less: the pump at its compensator) and where the overlap
takes ``MATTERS`` or more; the levels it leaves alone give the gain ``g`` every level shares
(the pump's displacement and speed).  Each level's shortfall ``1 - r / g`` against the
overlap's ``1 - s``, least squares through the origin, is the share of the probe overlap
the held flows bear out (nearly linear: an overlap ``o`` takes ``o / (1 - o)`` of a level's
opening share).  Its shape decides what it is: an overlap takes more of the flow
at a smaller command, while a valve gain off its nominal or a spool held short of its
command by the flow force takes about the same share at every level (the third plant's
slow spool s730896_39: 9-11 % at 28-48 %); a shortfall that the overlap's shape does not fit
better than a like one at every level shows no overlap.  Resampling the held levels gives
the share of resamples reading ``MIN_OVERLAP_PCT`` or more.  No simulation beyond the
probe overlap's.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from monitor.gap.data.prepare import ROD_VEL, Prepared
from monitor.gap.data.segments import Segment
from monitor.signals import SAMPLE_PERIOD_S
from monitor.sim import laws
from monitor.sim.machine import BAR, LPM, MachineParams

#: The probe overlap (% stroke): the catalogue's default, one hypothesis for every recording
#: (the fitted overlap's own simulation moves the pump's pressure at more levels the
#: larger it is, and reads a different set of levels).
PROBE_PCT = 10.0
#: The flows read: the pump's, and the rod's where a stroke sensor gives it.
FLOWS = ("QP", "RodVel")
#: A held command: steady within this (% stroke) for ``HOLD_S`` (s), out of centre.
STEADY_PCT = 0.2
HOLD_S = 0.4
CENTRE_PCT = 2.0
#: Left to settle at the start of a held command (s).
SETTLE_S = 0.2
#: A held level counts where the probe overlap takes this share of its flow or more.
MATTERS = 0.05
#: A level the valve sets: the overlap moves the pump's pressure there by this or less (bar).
PP_MOVED_BAR = 5.0
#: Fewer such levels (or levels where it takes nothing) than this: the held flows say
#: nothing.
MIN_LEVELS = 3
#: The least overlap (% stroke) the held flows must read to show a deadband: another make's
#: metering at small openings reads as a little (seven healthy machines of the third
#: plant's two development draws: -1.0 to 2.4 %, its small deadbands 5-7 %).
MIN_OVERLAP_PCT = 3.5
RESAMPLES = 400


@dataclass(frozen=True)
class HeldFlow:
    """The overlap (% stroke) the held flows read against a probe overlap's."""

    overlap_pct: float
    probe_pct: float
    levels: int
    #: The overlap's shape against a shortfall alike at every level (squared residuals).
    shape_ratio: float
    #: Share of resamples of the held levels reading ``MIN_OVERLAP_PCT`` or more (0 where
    #: the shortfall is not in the overlap's shape: ``shape_ratio`` 1 or more).
    share: float

    def as_dict(self) -> dict:
        return {
            "overlap_pct": round(self.overlap_pct, 1),
            "probe_overlap_pct": round(self.probe_pct, 1),
            "held_levels": self.levels,
            "shape_vs_alike": round(self.shape_ratio, 3),
            "share": round(self.share, 3),
        }


def held(cmd: np.ndarray, segments: Sequence[Segment]) -> list[tuple[int, int]]:
    """Rows ``lo .. hi`` (exclusive) of the settled part of every held command out of centre,
    within the segments' scored rows."""
    hold, settle = _samples(HOLD_S), _samples(SETTLE_S)
    out: list[tuple[int, int]] = []
    for seg in segments:
        i, stop = seg.score_from, seg.stop + 1
        while i < stop:
            j = i + 1
            while j < stop and abs(cmd[j] - cmd[i]) < STEADY_PCT:
                j += 1
            if j - i >= hold and abs(cmd[i]) > CENTRE_PCT:
                out.append((i + settle, j))
            i = j
    return out


def _samples(seconds: float) -> int:
    return int(round(seconds / SAMPLE_PERIOD_S))


def _means(x: np.ndarray, windows: list[tuple[int, int]]) -> np.ndarray:
    out = np.full(len(windows), np.nan)
    for k, (lo, hi) in enumerate(windows):
        v = x[lo:hi]
        v = v[np.isfinite(v)]
        if len(v):
            out[k] = v.mean()
    return out


def measure(
    prep: Prepared,
    segments: Sequence[Segment],
    pred: dict[str, np.ndarray],
    overlapped: dict[str, np.ndarray],
    probe_pct: float,
) -> HeldFlow | None:
    """The overlap the held flows of the recording read, ``pred`` the calibrated simulator
    and ``overlapped`` the same with an overlap of ``probe_pct``; None with fewer than
    ``MIN_LEVELS`` held levels where that overlap matters or where it does not."""
    windows = held(prep.cmd["SpoolCmd"], segments)
    r_rows, s_rows = [], []
    for name in (n for n in FLOWS if n in prep.meas and n in pred and n in overlapped):
        m, p = _means(prep.meas[name], windows), _means(pred[name], windows)
        q = _means(overlapped[name], windows)
        top = np.nanmax(np.abs(p)) if np.isfinite(p).any() else 0.0
        ok = np.isfinite(m + p + q) & (np.abs(p) > 0.05 * top)
        r_rows.append(np.where(ok, m / np.where(ok, p, 1.0), np.nan))
        s_rows.append(np.where(ok, q / np.where(ok, p, 1.0), np.nan))
    if not r_rows:
        return None
    # Per level, the mean over the flows read there.
    r, s = _level_means(np.array(r_rows)), _level_means(np.array(s_rows))
    found = np.isfinite(r + s)
    # Where the overlap moves the pump's pressure, the simulator's pump set the flow there
    # and the overlap hands it to the valve: how much it takes then hangs on the pump's
    # margin, not on the overlap.  Only levels the valve already set are read.
    pp_moved = np.abs(_means(overlapped["PP"], windows) - _means(pred["PP"], windows))
    valve_set = np.isfinite(pp_moved) & (pp_moved <= PP_MOVED_BAR)
    matters = found & valve_set & (s <= 1.0 - MATTERS)
    # Where the overlap takes (almost) nothing: the gain every level shares.
    shares = found & (np.abs(s - 1.0) <= MATTERS / 5)
    if matters.sum() < MIN_LEVELS or shares.sum() < MIN_LEVELS:
        return None
    r_m, s_m, r_g = r[matters], s[matters], r[shares]
    est, shape = _overlap(r_m, s_m, r_g, probe_pct)
    rng = np.random.default_rng(0)
    draws = np.empty(RESAMPLES)
    for i in range(RESAMPLES):
        pick = rng.integers(0, len(r_m), len(r_m))
        g_pick = rng.integers(0, len(r_g), len(r_g))
        draws[i] = _overlap(r_m[pick], s_m[pick], r_g[g_pick], probe_pct)[0]
    share = float(np.mean(draws >= MIN_OVERLAP_PCT)) if shape < 1.0 else 0.0
    return HeldFlow(est, probe_pct, int(matters.sum()), shape, share)


def _level_means(rows: np.ndarray) -> np.ndarray:
    """Per column, the mean of its finite values (NaN where none)."""
    ok = np.isfinite(rows)
    n = ok.sum(axis=0)
    total = np.where(ok, rows, 0.0).sum(axis=0)
    return np.where(n > 0, total / np.maximum(n, 1), np.nan)


def _overlap(
    r: np.ndarray, s: np.ndarray, r_shared: np.ndarray, probe_pct: float
) -> tuple[float, float]:
    """The probe overlap times the share of its flow shortfall the held levels bear out
    (each level's shortfall against the shared gain, ``1 - r / g``, over the overlap's,
    ``1 - s``, least squares through the origin), and how well that shape fits against a
    shortfall alike at every level (a valve's gain, a spool held short of its command):
    the ratio of their squared residuals, below 1 where the overlap's shape fits better."""
    g = float(np.median(r_shared))
    if g <= 0.0:
        return 0.0, np.inf
    short, own = 1.0 - r / g, 1.0 - s
    b = float(np.sum(short * own) / np.sum(own * own))
    sse_overlap = float(np.sum((short - b * own) ** 2))
    sse_alike = float(np.sum((short - short.mean()) ** 2))
    return b * probe_pct, sse_overlap / max(sse_alike, 1e-12)


# --- An overlap or a progressive metering curve (notches) --------------------------------
#
# An overlap ``o`` passes nothing until the spool has crossed it, then opens linearly;
# notches over the first ``n`` of the stroke pass a small flow growing with the square of the
# opening (``monitor.sim.laws.metering``).  Both bend the flow at small commands, and a
# linear simulator fitted to either names an overlap.  The held levels tell them apart,
# read by the orifice law alone (no simulation): at a held command ``A`` each metering edge
# passes ``Q = kv * a(A) * sqrt(dp)``, so the flow through it over the root of the drop the
# readings show across it is its open area ``a`` (times the valve's gain).  The meter-in edge
# passes the pump's flow (P->A raising, P->B lowering, across PP - PA or PP - PB); with the
# rod measured, the meter-out edge passes the rod's displaced flow (B->T, A->T, across PB or
# PA to tank).  The law ``g * metering(max(|A| - o, 0) / (1 - o), n)`` fitted on a grid of
# ``o`` and ``n`` (the gain ``g`` in closed form): a deadband reads ``o`` at its overlap
# whatever the notches do; a notched valve reads ``o`` near 0, the flow at its smallest
# commands small but there.

#: The grids (share of the stroke): the catalogue's overlaps, notches to 90 %.
OVERLAP_GRID = np.linspace(0.0, 0.30, 31)
NOTCH_GRID = np.linspace(0.0, 0.90, 46)
#: Fewer levels than ``MIN_LEVELS`` or than this below ``NEAR_CENTRE`` (share of the
#: stroke): the smallest commands are not held, the shapes not told.  Above it an overlap
#: with a smooth corner and notches both pass a flow growing with the command (the third
#: plant's smooth-cornered deadbands of 6-14 %, held at 25 % and up, read as notches over
#: 14-42 %); below it an overlap passes nothing or little, notches a small flow (the
#: fourth plant's healthy machines, held at 13-19 %: 0.022-0.046 of the full area).
NEAR_CENTRE = 0.20
MIN_NEAR = 2
#: A drop across an edge below this (bar) reads no area (laminar, or the noise).
MIN_DROP_BAR = 5.0
#: A rod this close to an end stop (mm) passes no flow whatever the valve's opening.
STOP_MARGIN_MM = 5.0
#: The held flows show a progressive curve where they read notches over ``MIN_NOTCH_PCT``
#: of the stroke or more in ``1 - RULED_OUT`` of the resamples and an overlap of
#: ``MIN_OVERLAP_PCT`` or more in ``RULED_OUT`` or fewer (a linear valve reads neither).
MIN_NOTCH_PCT = 10.0
RULED_OUT = 0.05


@dataclass(frozen=True)
class Metering:
    """The valve's curve near centre read from the held flows: the overlap with the notches
    free, and how the two pure shapes fit."""

    overlap_pct: float
    notch_pct: float
    levels: int
    near_centre: int
    #: Share of resamples of the levels reading ``MIN_OVERLAP_PCT`` or more of overlap.
    overlap_share: float
    #: Share of resamples reading notches over ``MIN_NOTCH_PCT`` or more of the stroke.
    notch_share: float
    #: Squared residuals of the best overlap alone (linear edges) over the best notches
    #: alone (no overlap): above 1 the notches' shape fits the held flows better.
    overlap_vs_notch: float
    #: Per level read: the command (%) and the open area the flows read (share of the
    #: fitted law's full-stroke area).
    points: tuple[tuple[float, float], ...]

    @property
    def progressive(self) -> bool:
        """Notches shown and an overlap ruled out: flow where an overlap would pass none."""
        return self.overlap_share <= RULED_OUT and self.notch_share >= 1.0 - RULED_OUT

    def as_dict(self) -> dict:
        return {
            "overlap_pct": round(self.overlap_pct, 1),
            "notch_pct": round(self.notch_pct, 1),
            "held_levels": self.levels,
            "near_centre": self.near_centre,
            "overlap_share": round(self.overlap_share, 3),
            "notch_share": round(self.notch_share, 3),
            "overlap_vs_notch": round(self.overlap_vs_notch, 3),
            "area_by_command": [[round(a, 1), round(b, 3)] for a, b in self.points],
        }


def open_area(command: np.ndarray, overlap: float, notch: float) -> np.ndarray:
    """The simulator's open area (share of full stroke) at ``command`` (share of the stroke):
    the overlap crossed, then the notches' metering by the simulator's own law (one rule:
    ``monitor.sim.laws.metering``, element by element)."""
    x = np.maximum(np.abs(command) - overlap, 0.0) / (1.0 - overlap)
    if notch <= 0.0:
        return x
    return np.array([laws.metering(float(v), notch) for v in x])


def edge_areas(
    prep: Prepared, windows: list[tuple[int, int]], machine: MachineParams
) -> np.ndarray:
    """Per held level, the open area its edges read (m^3/s per sqrt(Pa) over the valve's
    ``kv``: a share of the full-stroke area), the mean over the edges read; NaN where none
    (a drop below ``MIN_DROP_BAR``, the rod at a stop)."""
    m = {n: _means(prep.meas[n], windows) for n in ("PP", "PA", "PB", "QP")}
    cmd = _means(prep.cmd["SpoolCmd"], windows)
    rod = _means(prep.rod_mm, windows)
    free = (rod > STOP_MARGIN_MM) & (rod < prep.stroke_mm - STOP_MARGIN_MM)
    up, kv, tank = cmd > 0, machine.valve.valve_kv, machine.valve.tank_pa / BAR
    rows = [_area(m["QP"] * LPM, np.where(up, m["PP"] - m["PA"], m["PP"] - m["PB"]), kv)]
    if ROD_VEL in prep.meas:
        v = np.abs(_means(prep.meas[ROD_VEL], windows)) * 1e-3
        cyl = machine.cylinder
        out = np.where(up, cyl.area_b_m2 * v, cyl.area_a_m2 * v)
        rows.append(_area(out, np.where(up, m["PB"], m["PA"]) - tank, kv))
    return np.where(free, _level_means(np.array(rows)), np.nan)


def _area(q_m3_s: np.ndarray, drop_bar: np.ndarray, kv: float) -> np.ndarray:
    ok = np.isfinite(q_m3_s + drop_bar) & (drop_bar >= MIN_DROP_BAR)
    return np.where(ok, np.abs(q_m3_s) / (kv * np.sqrt(np.where(ok, drop_bar, 1.0) * BAR)), np.nan)


def metering(
    prep: Prepared, segments: Sequence[Segment], machine: MachineParams
) -> Metering | None:
    """The overlap and notches the held flows of the recording read (``machine``: the
    valve's gain and the cylinder's areas); None with fewer than ``MIN_LEVELS`` levels read
    or fewer than ``MIN_NEAR`` of them near centre."""
    windows = held(prep.cmd["SpoolCmd"], segments)
    cmd = _means(prep.cmd["SpoolCmd"], windows) / 100.0
    area = edge_areas(prep, windows, machine)
    ok = np.isfinite(area)
    near = ok & (np.abs(cmd) < NEAR_CENTRE)
    if ok.sum() < MIN_LEVELS or near.sum() < MIN_NEAR:
        return None
    a = area[ok]
    f, o, n = _curves(np.abs(cmd[ok]))
    k = _law(f, a)[0]
    g = float(f[k] @ a) / max(float(f[k] @ f[k]), 1e-12)
    rng = np.random.default_rng(0)
    draws = np.empty((RESAMPLES, 2))
    for i in range(RESAMPLES):
        pick = rng.integers(0, len(a), len(a))
        j = _law(f[:, pick], a[pick])[0]
        draws[i] = o[j], n[j]
    only_overlap = _law(f, a, n == 0.0)[1]
    only_notch = _law(f, a, o == 0.0)[1]
    return Metering(
        100.0 * o[k],
        100.0 * n[k],
        int(ok.sum()),
        int(near.sum()),
        float(np.mean(100.0 * draws[:, 0] >= MIN_OVERLAP_PCT)),
        float(np.mean(100.0 * draws[:, 1] >= MIN_NOTCH_PCT)),
        only_overlap / max(only_notch, 1e-12),
        tuple((100.0 * float(x), float(y) / g) for x, y in sorted(zip(cmd[ok], a, strict=True))),
    )


def _curves(c: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every grid law's open area at commands ``c``: rows (overlap, notch), and the two."""
    o_grid, n_grid = np.meshgrid(OVERLAP_GRID, NOTCH_GRID, indexing="ij")
    o, n = o_grid.ravel(), n_grid.ravel()
    rows = [open_area(c, float(a), float(b)) for a, b in zip(o, n, strict=True)]
    return np.array(rows), o, n


def _law(f: np.ndarray, a: np.ndarray, rows: np.ndarray | None = None) -> tuple[int, float]:
    """The grid law (row of ``f``, among ``rows``) whose curve times its best gain fits
    the open areas ``a`` best, and its squared residuals (closed form in the gain)."""
    if rows is not None:
        f = f[rows]
    ff = np.einsum("gl,gl->g", f, f)
    fa = f @ a
    sse = float(a @ a) - np.where(ff > 0.0, fa * fa / np.where(ff > 0.0, ff, 1.0), 0.0)
    k = int(np.argmin(sse))
    return (k if rows is None else int(np.flatnonzero(rows)[k])), float(max(sse[k], 0.0))
