"""Rod speed per pump flow: the kinematics a sensor calibration hypothesis must keep.

A physical effect changes the flow and the rod alike (pump leakage slows the rod by as much
as it cuts QP); a flow meter or stroke sensor error changes one of the two.  Split from
``sensorcal.py`` (which fits the gain and offset) with the row helpers both use.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from monitor.gap.data.prepare import ROD_VEL, Prepared, rod_velocity
from monitor.gap.data.segments import Segment
from monitor.sim.effects import Effect


def scored_rows(segments: Sequence[Segment]) -> np.ndarray:
    """The scored rows of ``segments``, concatenated."""
    return np.concatenate([np.arange(s.score_from, s.stop) for s in segments])


def velocity_base(prep: Prepared, segments: Sequence[Segment], col: str) -> np.ndarray:
    """What a prediction of ``col`` holds besides the sensor's own reading: 0, except for the
    rod velocity, which ``predict.sense`` builds as measured + simulated - measured filtered
    within the segment (so a gain scales only the simulated part)."""
    out = np.zeros(len(prep))
    if col == ROD_VEL:
        for seg in segments:
            rows = slice(seg.start, seg.stop + 1)
            out[rows] = prep.meas[ROD_VEL][rows] - rod_velocity(prep.rod_mm[rows])
    return out


#: Kinematics a flow or rod-position error must leave consistent (relative): read through
#: the hypothesis, measured rod speed per measured pump flow must match the simulator's
#: within this, or at least not be further off than without the hypothesis.
KINEMATIC_TOLERANCE = 0.03
#: Rows for the kinematic check: flow and rod speed well above their noise, spool open.
_MIN_FLOW_LPM, _MIN_SPEED_MM_S, _MIN_SPOOL_PCT = 5.0, 10.0, 10.0


def kinematic_ratio(
    prep: Prepared,
    rows: np.ndarray,
    q_sim: np.ndarray,
    v_sim: np.ndarray,
    q_meas: np.ndarray,
    v_meas: np.ndarray,
) -> float | None:
    """Measured rod speed per pump flow over the simulator's (medians on extension rows
    with flow and speed well above noise); None with too few such rows."""
    # Extension: QP all goes to the cap side.
    ok = _extending(prep, rows, q_sim, v_sim, q_meas, v_meas)
    if ok.sum() < 50:
        return None
    return float(np.median(v_meas[ok] / q_meas[ok]) / np.median(v_sim[ok] / q_sim[ok]))


def _extending(
    prep: Prepared,
    rows: np.ndarray,
    q_sim: np.ndarray,
    v_sim: np.ndarray,
    q_meas: np.ndarray,
    v_meas: np.ndarray,
) -> np.ndarray:
    """Extension rows with flow and speed well above noise (``kinematic_ratio``'s)."""
    return (
        (prep.cmd["SpoolCmd"][rows] > _MIN_SPOOL_PCT)
        & (q_meas > _MIN_FLOW_LPM)
        & (q_sim > _MIN_FLOW_LPM)
        & (v_meas > _MIN_SPEED_MM_S)
        & (v_sim > _MIN_SPEED_MM_S)
    )


def _read_through(
    prep: Prepared, segments: Sequence[Segment], base: dict[str, np.ndarray], effect: Effect | None
) -> tuple[np.ndarray, ...]:
    """Scored rows' measured QP and rod speed (read through ``effect``'s inverse) and the
    simulator's: ``q_meas, v_meas, q_sim, v_sim``."""
    rows = scored_rows(segments)
    q_meas, v_meas = prep.meas["QP"][rows], prep.meas[ROD_VEL][rows]
    v_sim = base[ROD_VEL][rows] - velocity_base(prep, segments, ROD_VEL)[rows]
    q_sim = base["QP"][rows]
    if effect is not None and effect.labels["signal"] == "QP":
        q_meas = (q_meas - effect.params["offset"]) / effect.params["gain"]
    elif effect is not None and effect.labels["signal"] == "RodPos":
        v_meas = v_meas / effect.params["gain"]
    return q_meas, v_meas, q_sim, v_sim


def segment_speeds_per_flow(
    prep: Prepared, segments: Sequence[Segment], base: dict[str, np.ndarray], effect: Effect | None
) -> tuple[np.ndarray, np.ndarray]:
    """Per segment, summed over its extension rows (``kinematic_ratio``'s): measured rod
    speed per measured pump flow (read through ``effect``'s inverse), and the simulator's;
    their sums over any resample of the segments give that resample's ratio."""
    q_meas, v_meas, q_sim, v_sim = _read_through(prep, segments, base, effect)
    ok = _extending(prep, scored_rows(segments), q_sim, v_sim, q_meas, v_meas)
    seg = np.repeat(np.arange(len(segments)), [s.stop - s.score_from for s in segments])
    with np.errstate(invalid="ignore", divide="ignore"):
        meas = np.where(ok, v_meas / q_meas, 0.0)
        sim = np.where(ok, v_sim / q_sim, 0.0)
    n = len(segments)
    return np.bincount(seg, meas, n), np.bincount(seg, sim, n)


def kinematic_mismatch(
    prep: Prepared, segments: Sequence[Segment], base: dict[str, np.ndarray], effect: Effect | None
) -> float | None:
    """|log| of (measured rod speed / pump flow) over the simulator's, with the measured QP
    or RodPos read through ``effect``'s inverse; None without RodPos or enough motion.

    A physical effect changes the flow and the rod alike (pump leakage slows the rod by as
    much as it cuts QP); a flow meter or stroke sensor error changes one of the two.  This is
    what tells a QP or RodPos gain from leakage or friction, which can mimic it in the
    residual of the signal alone (and, for RodPos, through the start states)."""
    if ROD_VEL not in base:
        return None
    q_meas, v_meas, q_sim, v_sim = _read_through(prep, segments, base, effect)
    ratio = kinematic_ratio(prep, scored_rows(segments), q_sim, v_sim, q_meas, v_meas)
    return None if ratio is None else abs(float(np.log(ratio)))


def kinematically_consistent(
    prep: Prepared, segments: Sequence[Segment], base: dict[str, np.ndarray], effect: Effect
) -> bool:
    """Whether a QP or RodPos hypothesis keeps rod speed and pump flow consistent (other
    signals: always)."""
    if effect.labels["signal"] not in ("QP", "RodPos"):
        return True
    after = kinematic_mismatch(prep, segments, base, effect)
    before = kinematic_mismatch(prep, segments, base, None)
    if after is None or before is None:
        return True
    return after <= KINEMATIC_TOLERANCE or after <= before
