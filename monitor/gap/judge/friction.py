"""Rod friction read from the recording's own force balance: Coulomb against viscous.

While the rod moves, the hydraulic force PA A_A - PB A_B balances the load, the inertia
and the friction: F = G + k (x - x_ref) + c v + F_c sign(v) + m a.  Coulomb friction is
odd in speed and constant in size, viscous friction odd and proportional to speed, the
gravity load even: regressed on moving samples, each has a column of its own, whatever
tolerance the simulator's calibration gave them.  The calibration cannot tell the two
frictions apart where the rod moves at much the same speed in each direction (on the
outsider's duty cycle sign(v) and v have a cosine of 0.97): a 300-800 N Coulomb friction
then passes for viscous friction at +30 % and more.  So the viscous coefficient is held
within the band the tolerance calibration allows (``calibrate.TOLERANCES``, +-30 % of
the configured value): what the band cannot carry is Coulomb friction, and a viscous
coefficient that ends on the band's edge is reported as evidence.

PA and PB are read where the sensors sit, not in the chambers: a pressure sensor at the
valve's work port reads the chamber pressure plus the drop across the hose and its
fittings, a turbulent drop growing with the square of the flow (Q_A = A_A v into A, A_B v
out of B), which adds r v |v| to the force with r = K (A_A^3 + A_B^3) >= 0 (K the
restriction's dp / Q^2).  Held in its band, the viscous coefficient cannot carry it, and
the Coulomb column took it: on the fourth plant (PA and PB read behind hose
restrictions, 1-1.5 bar at 30 L/min) healthy machines read 137-203 N of Coulomb friction
in 98-100 % of resamples beside viscous friction at the band's top (free, 4900-6000 N
s/m).  So the balance has a column of its own for that drop, never negative (a drop
opposes the flow), read with the viscous coefficient free and then held while the
frictions are read (``_bounded``), and only where the rod's speeds are far enough apart to
tell a square of the speed from a line (``SLOW_SAMPLES``).  Healthy machines there then
read -8 to 4 N beside 1930-2680 N s/m free and a drop of 15 000-18 000 N s^2/m^2.

No simulation: the recording alone.  The blocks of the bootstrap are the diagnosis's
segments (each a move or two started from rest), so a few segments with a force the
balance does not describe cannot carry the estimate.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from monitor.gap.data.prepare import Prepared, rod_velocity, smooth_rod
from monitor.gap.data.segments import Segment
from monitor.gap.fit.calibrate import BY_NAME
from monitor.gap.fit.candidates import Candidate
from monitor.gap.fit.score import SegmentSums
from monitor.gap.judge.decide import SIGNIFICANT, Decision, boot_gain, trades_signals
from monitor.gap.judge.shrink import resamples
from monitor.signals import SAMPLE_PERIOD_S
from monitor.sim.machine import BAR, MachineParams

#: Coulomb friction (N) the balance must find before a friction is read from it: a quarter
#: of the least the benchmarks' plants draw (300 N); healthy machines of the development
#: seeds and every other effect -38 to 25 N, frictions of 300-900 N 275-562 N (with
#: viscous friction held in its band).
LEVEL_N = 100.0
#: Rod speed (mm/s) below which the sign of the velocity is not read (a 0.5 mm RodPos noise
#: gives 3 mm/s on the smoothed difference).
MIN_SPEED_MM_S = 5.0
#: Acceleration (mm/s^2) above which a sample is left out: starts and stops, where the
#: pressures ring and the inertia term would carry the fit.
MAX_ACCEL_MM_S2 = 300.0
#: Rows this close (mm) to either end of the stroke are left out (an end stop's force).
STOP_MARGIN_MM = 15.0
#: The balance is read only when its residual rms (N) is below this (5 % of the reference
#: machine's gravity load): 120-210 N on the development recordings, 490-3800 N where a
#: pressure gain, a periodic force or a rod path integrated from a slow pump's flow broke
#: it (there the Coulomb column took up to 5 kN).
MAX_RMS_N = 300.0
#: Least moving samples (10 s of motion at 100 Hz).
MIN_SAMPLES = 1000
#: The catalogue effect this reads.
NAME = "cylinder_friction"
#: Columns of the regression: gravity (N), its slope (N/mm), viscous friction (N s/m),
#: Coulomb friction (N), mass (kg), the drop between chambers and sensors (N s^2/m^2).
VISCOUS, _COULOMB, QUADRATIC = 2, 3, 5
#: Speed (m/s) at which the evidence says what that drop adds to the force.
_AT_SPEED_M_S = 0.15
#: The drop is read only where the rod moves at speeds far enough apart to tell a square
#: from a line: this many moving samples (1 s) at ``CLEAR_SPEED_MM_S`` or more but below
#: half the median of those speeds.  A duty cycle that moves the rod at one speed each way
#: has 0-18 (the outsider's and the third plant's, this simulator's boom cycle: there a
#: drop read anyway took 15-35 % of the viscous coefficient), the fourth plant's 183-2141,
#: this simulator's spool ramps 362.
SLOW_SAMPLES = 100
CLEAR_SPEED_MM_S = 20.0


@dataclass(frozen=True)
class FrictionSignature:
    """What the force balance of the moving rod says about its friction."""

    coulomb_n: float
    viscous_n_s_m: float
    #: The viscous coefficient's band (N s/m) and which edge it ended on (-1, 0, +1).
    viscous_band: tuple[float, float]
    viscous_at_bound: int
    #: Share of bootstrap resamples of the segments with Coulomb friction at ``LEVEL_N`` or
    #: more.
    above_share: float
    rms_n: float
    samples: int
    #: The balance describes the recording (enough samples, residual below ``MAX_RMS_N``).
    readable: bool
    #: The same with viscous friction free (any value): Coulomb friction, and its share of
    #: resamples at ``LEVEL_N`` or more.  Where the rod moves at much the same speed each
    #: way, a free viscous coefficient takes the Coulomb friction too (the outsider's
    #: 300-800 N friction: 20 N beside 4500 N s/m), and so would a band that held a scored
    #: rod's viscous friction take it for Coulomb friction.
    free_coulomb_n: float = 0.0
    free_share: float = 0.0
    #: The force growing with the square of the speed (N s^2/m^2, held >= 0): the pressure
    #: drop between the chambers and where PA and PB are read, beside the frictions.
    quadratic_n_s2_m2: float = 0.0

    @property
    def present(self) -> bool:
        return self.readable and self.above_share >= SIGNIFICANT

    @property
    def separated(self) -> bool:
        """Coulomb friction whatever the viscous friction: no tolerance can carry it."""
        return self.present and self.free_share >= SIGNIFICANT

    @property
    def absent(self) -> bool:
        return self.readable and self.above_share <= 1.0 - SIGNIFICANT

    def evidence(self) -> str:
        if not self.readable:
            return (
                f"the rod's force balance does not describe this recording ({self.samples} "
                f"moving samples, residual {self.rms_n:.0f} N rms): friction not read from it"
            )
        bound = {1: " (at its band's top)", -1: " (at its band's bottom)"}.get(
            self.viscous_at_bound, ""
        )
        free = (
            f"with viscous friction free {self.free_coulomb_n:.0f} N "
            f"({100 * self.free_share:.0f} %)"
        )
        drop = self.quadratic_n_s2_m2 * _AT_SPEED_M_S**2
        quad = (
            f" and a drop between the chambers and the pressure sensors growing with the "
            f"square of the speed ({drop:.0f} N at {1e3 * _AT_SPEED_M_S:.0f} mm/s)"
            if drop >= 0.5 * LEVEL_N
            else ""
        )
        return (
            f"the rod's force balance: Coulomb friction {self.coulomb_n:.0f} N beside viscous "
            f"friction {self.viscous_n_s_m:.0f} N s/m{bound}{quad}, at {LEVEL_N:.0f} N or "
            f"more in {100 * self.above_share:.0f} % of the resamples; {free}"
        )

    def as_dict(self) -> dict:
        return {
            "coulomb_n": round(self.coulomb_n, 1),
            "viscous_n_s_m": round(self.viscous_n_s_m, 1),
            "viscous_band_n_s_m": [round(v, 1) for v in self.viscous_band],
            "viscous_at_bound": self.viscous_at_bound != 0,
            "level_n": LEVEL_N,
            "above_share": round(self.above_share, 3),
            "free_coulomb_n": round(self.free_coulomb_n, 1),
            "free_above_share": round(self.free_share, 3),
            "separated": self.separated,
            "quadratic_n_s2_m2": round(self.quadratic_n_s2_m2, 1),
            "rms_n": round(self.rms_n, 1),
            "samples": self.samples,
            "readable": self.readable,
            "evidence": self.evidence(),
        }


def signature(
    prep: Prepared, segments: Sequence[Segment], machine: MachineParams
) -> FrictionSignature:
    """The friction the moving rod's measured force balance shows (``segments``: the
    bootstrap's blocks)."""
    nominal = machine.load.viscous_friction_n_s_m
    band = BY_NAME["viscous_friction"].band
    bounds = (nominal * (1.0 - band), nominal * (1.0 + band))
    xtx, xty, yty, n = balance_sums(prep, segments, machine)
    total = (xtx.sum(axis=0), xty.sum(axis=0), float(yty.sum()), int(n.sum()))
    if total[3] < MIN_SAMPLES:
        return FrictionSignature(0.0, nominal, bounds, 0, 0.0, np.inf, total[3], False)
    beta, side = _bounded(total[0], total[1], bounds)
    sq = total[2] - 2 * beta @ total[1] + beta @ total[0] @ beta
    rms = float(np.sqrt(max(sq, 0.0) / total[3]))
    idx = resamples(len(segments), seed=1)
    free = (-np.inf, np.inf)
    boot = np.array(
        [
            [
                _bounded(xtx[i].sum(axis=0), xty[i].sum(axis=0), b)[0][_COULOMB]
                for b in (bounds, free)
            ]
            for i in idx
        ]
    )
    above = np.mean(boot >= LEVEL_N, axis=0)
    return FrictionSignature(
        coulomb_n=float(beta[_COULOMB]),
        viscous_n_s_m=float(beta[VISCOUS]),
        viscous_band=bounds,
        viscous_at_bound=side,
        above_share=float(above[0]),
        rms_n=rms,
        samples=total[3],
        readable=rms <= MAX_RMS_N,
        free_coulomb_n=float(_bounded(total[0], total[1], free)[0][_COULOMB]),
        free_share=float(above[1]),
        quadratic_n_s2_m2=float(beta[QUADRATIC]),
    )


def balance_sums(
    prep: Prepared, segments: Sequence[Segment], machine: MachineParams
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per segment, the normal equations' sums of the moving rod's force balance (columns:
    gravity, its slope, viscous friction, Coulomb friction, mass, the sensors' drop
    growing with the square of the speed)."""
    cyl = machine.cylinder
    force = (prep.meas["PA"] * cyl.area_a_m2 - prep.meas["PB"] * cyl.area_b_m2) * BAR
    v = rod_velocity(smooth_rod(prep.rod_mm))
    a = np.gradient(v, SAMPLE_PERIOD_S)
    x = prep.rod_mm
    ok = (
        prep.valid
        & np.isfinite(force)
        & (np.abs(v) >= MIN_SPEED_MM_S)
        & (np.abs(a) <= MAX_ACCEL_MM_S2)
        & (x > STOP_MARGIN_MM)
        & (x < prep.stroke_mm - STOP_MARGIN_MM)
    )
    if prep.unscored is not None:
        ok &= ~prep.unscored
    v_m_s = v * 1e-3
    slope = x - x[ok].mean() if ok.any() else x
    # A column of zeros where the speeds cannot tell the drop from viscous friction: its
    # coefficient is then zero (least squares' least-norm solution).
    drop = v_m_s * np.abs(v_m_s) if _speeds_apart(np.abs(v[ok])) else np.zeros_like(v)
    cols = np.column_stack([np.ones_like(v), slope, v_m_s, np.sign(v), a * 1e-3, drop])
    return _segment_sums(cols, force, ok, segments)


def _speeds_apart(speed_mm_s: np.ndarray) -> bool:
    """Whether the rod moved at speeds far enough apart to read the drop (``SLOW_SAMPLES``)."""
    clear = speed_mm_s[speed_mm_s >= CLEAR_SPEED_MM_S]
    if clear.size == 0:
        return False
    return int(np.sum(clear < 0.5 * np.median(clear))) >= SLOW_SAMPLES


def _segment_sums(
    cols: np.ndarray, y: np.ndarray, ok: np.ndarray, segments: Sequence[Segment]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per segment, the normal equations' sums over its usable rows."""
    k = cols.shape[1]
    xtx, xty = np.zeros((len(segments), k, k)), np.zeros((len(segments), k))
    yty, n = np.zeros(len(segments)), np.zeros(len(segments), dtype=np.int64)
    for j, seg in enumerate(segments):
        rows = np.arange(seg.score_from, seg.stop)
        rows = rows[ok[rows]]
        xs, ys = cols[rows], y[rows]
        xtx[j], xty[j], yty[j], n[j] = xs.T @ xs, xs.T @ ys, ys @ ys, len(rows)
    return xtx, xty, yty, n


def _bounded(
    xtx: np.ndarray, xty: np.ndarray, bounds: tuple[float, float]
) -> tuple[np.ndarray, int]:
    """Least squares with the viscous coefficient held within ``bounds``, and which edge
    of them it ended on.  The drop growing with the square of the speed is read first with
    the viscous coefficient free (``readout``), where only a curvature of the force over
    speed can carry it: a friction bends the force the other way, and on a duty cycle that
    moves the rod at one speed each way the drop reads nothing.  Then it is held there:
    with the viscous coefficient held in its band, the drop and the Coulomb friction would
    share whatever the band refuses, and a friction at one speed looks like either."""
    drop = readout(xtx, xty)
    if not (np.isfinite(bounds[0]) or np.isfinite(bounds[1])):
        return drop, 0
    return _least(xtx, xty, bounds, drop[QUADRATIC])


def readout(xtx: np.ndarray, xty: np.ndarray) -> np.ndarray:
    """The balance's coefficients with every one free but the quadratic drop, held at zero
    or more (what ``thinoil`` reads the viscous friction from)."""
    return _least(xtx, xty, (-np.inf, np.inf), None)[0]


def _least(
    xtx: np.ndarray, xty: np.ndarray, bounds: tuple[float, float], drop: float | None
) -> tuple[np.ndarray, int]:
    """Least squares with the viscous coefficient within ``bounds`` and the drop held at
    ``drop`` (None: zero or more).  A convex quadratic's minimum over a box is the least
    of its minima on the box's faces that lie in the box: each coefficient free or on one
    of its edges."""
    best, cost, side = np.zeros(len(xty)), np.inf, 0
    edges = [(None, 0)] + [(b, s) for b, s in ((bounds[0], -1), (bounds[1], 1)) if np.isfinite(b)]
    for c, c_side in edges:
        for q in (None, 0.0) if drop is None else (drop,):
            beta = _on_face(xtx, xty, {VISCOUS: c, QUADRATIC: q})
            inside = bounds[0] <= beta[VISCOUS] <= bounds[1] and beta[QUADRATIC] >= 0.0
            here = float(beta @ xtx @ beta - 2.0 * beta @ xty)
            if inside and here < cost:
                best, cost, side = beta, here, c_side
    return best, side


def _on_face(xtx: np.ndarray, xty: np.ndarray, fixed: dict[int, float | None]) -> np.ndarray:
    """Least squares with the coefficients ``fixed`` names held at their values (None:
    free)."""
    held = {j: v for j, v in fixed.items() if v is not None}
    keep = [j for j in range(len(xty)) if j not in held]
    rhs = xty[keep] - sum((xtx[keep, j] * v for j, v in held.items()), np.zeros(len(keep)))
    out = np.empty(len(xty))
    out[keep] = np.linalg.lstsq(xtx[np.ix_(keep, keep)], rhs, rcond=None)[0]
    for j, v in held.items():
        out[j] = v
    return out


def named_by_signature(
    sig: FrictionSignature,
    friction: Candidate,
    before: SegmentSums,
    after: SegmentSums,
    idx: np.ndarray,
    floor: np.ndarray,
) -> Decision | None:
    """``cylinder_friction`` named on the force balance's evidence (None: not named).

    The balance shows a Coulomb friction the viscous band cannot carry (``present``), and
    the friction's fit, added to the simulator it is judged against (``before``: the
    calibrated one, or its own tolerances where the calibration absorbed it), gains on the
    held-out part in ``SIGNIFICANT`` of the block-bootstrap resamples without making a
    signal clearly worse.  The held-out share it must otherwise remove (half the gap, or
    the practical level of the structured gap) guards against an effect fitted to a
    healthy machine's base mismatch; here the recording's own force balance, which a base
    mismatch of the valve, pump or lines does not enter, says that the rod has friction,
    and the held-out test says that the fitted friction is the recording's.  A friction
    that removes 10-40 % of a gap dominated by another plant's base dynamics is named."""
    if sig.separated:
        return Decision(NAME, None, friction, min(sig.above_share, sig.free_share))
    if not sig.present:
        return None
    gain = boot_gain(before, after, idx, floor)
    if np.mean(gain > 0) < SIGNIFICANT:
        return None
    if trades_signals(friction, before, after, idx, floor) is not None:
        return None
    return Decision(NAME, None, friction, float(np.mean(gain > 0)))
