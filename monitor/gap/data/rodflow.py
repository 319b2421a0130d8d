"""Rod position without RodPos: pump flow integrated into the side the spool opens, anchored
where the recording shows the rod on an end stop.

Integrated flow is only known up to the rod's starting position, and clipping at the stroke
re-anchors it only when the estimate runs *ahead* of the rod.  An estimate that starts
behind (the recording begins with the rod at 50 mm, the integration at 0) never clips: a
boom cycle that runs into the top stop every time kept it 45-50 mm short for the whole
recording, so segments started at a hold after a stop put the simulated rod in mid-stroke
while the real one sat on the stop.  With its trapped chamber pressurised to the pump's
pressure, the simulated rod then ran on, compressed the other chamber to 185 bar where the
recording read 0, and the gap (PB NRMSE 0.95) was too large for any effect to matter.

A stall says where the rod is.  With the spool open, the pump at its pressure limit, no pump
flow and the opened chamber at the pump's pressure (no flow, so no drop across the open
metering edge), nothing moves while the full pressure pushes the rod: it is on the stop
that side drives it to.  A closed or overlapped valve also stops the flow but keeps the
chamber at its holding pressure, which tells it apart.  So does a hold whose rod force is
far off the gravity load (a spool that closed just as the rod reached the stop).

The moment of arrival on a stop is left out of the comparison (``arrivals``): the integral's
few millimetres put the simulated arrival tens of milliseconds early or late.
"""

from __future__ import annotations

import numpy as np

from monitor.signals import SAMPLE_PERIOD_S
from monitor.sim.machine import BAR, LPM, MachineParams

#: Spool commands within this of centre count as closed (%); segments split holds by it too.
CENTRE_PCT = 1.0
#: A stall needs the spool opened by at least this (%) ...
STALL_SPOOL_PCT = 10.0
#: ... pump flow below this (L/min; a moving boom draws several) ...
STALL_FLOW_LPM = 1.0
#: ... the pump pressure at this share of its limit (compensator start or relief crack, the
#: lower) or more ...
STALL_PP_SHARE = 0.8
#: ... the opened chamber within this share of the pump pressure ...
STALL_CHAMBER_SHARE = 0.9
#: ... for this long (s): flow and pressures pass through such values briefly on a reversal.
STALL_S = 0.1
#: Not compared around a stall's onset, before and after it (s): the simulated rod's start
#: position is only as good as the integral (6 mm at the 90th percentile on holds of the
#: development recordings, against RodPos), which at 100 mm/s is 60 ms early or late on
#: the stop, and a 150 bar pressure step 70 ms off outweighs the residual of the rest of
#: its segment a hundredfold.
ARRIVAL_BEFORE_S = 0.15
ARRIVAL_AFTER_S = 0.1
#: A hold on a stop: the spool centred and the hydraulic force on the rod (PA A_A - PB A_B)
#: off the gravity load by more than this multiple of it, for ``STALL_S``.  A rod held in
#: mid-stroke balances gravity within its tolerance (15 %) and breakaway friction (up to
#: 2 kN in the catalogue's range, a third of this boom's 6 kN), and a pressure sensor read
#: up to 20 bar off (the largest offset ``sensor_calibration`` names) moves the computed
#: force by 6 kN more; pressed on a stop it need not balance at all (a spool that closes
#: as the rod arrives traps 90 bar in A: 22 kN off).
HOLD_OFF_BALANCE = 1.5
#: The rod has left a stop once the integral is this far from it (mm); found on the same
#: stop again without leaving it (a hold after a stall), it has not arrived.
ARRIVED_MM = 3.0
_STALL_N = max(int(round(STALL_S / SAMPLE_PERIOD_S)), 1)  # samples a stall must last


def stalls(
    spool: np.ndarray,
    pp_bar: np.ndarray,
    pa_bar: np.ndarray,
    pb_bar: np.ndarray,
    qp_lpm: np.ndarray,
    machine: MachineParams,
) -> np.ndarray:
    """Per sample: +1 where the rod sits on the top stop (extension stalled), -1 on the
    bottom stop (retraction stalled), 0 elsewhere (including the first ``STALL_S``)."""
    limit_pa = machine.line.relief_crack_pa
    if machine.pump.compensator_enabled:
        limit_pa = min(machine.pump.compensator_start_pa, limit_pa)
    limit_bar = limit_pa / BAR
    pp = np.nan_to_num(pp_bar)
    common = (np.nan_to_num(qp_lpm, nan=np.inf) < STALL_FLOW_LPM) & (
        pp >= STALL_PP_SHARE * limit_bar
    )
    ext = common & (spool > STALL_SPOOL_PCT) & (np.nan_to_num(pa_bar) >= STALL_CHAMBER_SHARE * pp)
    ret = common & (spool < -STALL_SPOOL_PCT) & (np.nan_to_num(pb_bar) >= STALL_CHAMBER_SHARE * pp)
    return np.where(_held(ext, _STALL_N), 1, np.where(_held(ret, _STALL_N), -1, 0)).astype(np.int8)


def holds_on_stop(
    spool: np.ndarray, pa_bar: np.ndarray, pb_bar: np.ndarray, machine: MachineParams
) -> np.ndarray:
    """Per sample: +1 where a centred spool holds the rod on the top stop, -1 on the bottom
    one (``HOLD_OFF_BALANCE``), 0 elsewhere."""
    force = (
        np.nan_to_num(pa_bar) * machine.cylinder.area_a_m2
        - np.nan_to_num(pb_bar) * machine.cylinder.area_b_m2
    )
    off = force * BAR - machine.load.gravity_load_n
    centred = np.abs(spool) < CENTRE_PCT
    margin = HOLD_OFF_BALANCE * abs(machine.load.gravity_load_n)
    top = _held(centred & (off > margin), _STALL_N)
    bottom = _held(centred & (off < -margin), _STALL_N)
    return np.where(top, 1, np.where(bottom, -1, 0)).astype(np.int8)


def arrivals(flagged: np.ndarray, n: int) -> np.ndarray:
    """Per sample of ``n``: True within ``ARRIVAL_BEFORE_S`` before to ``ARRIVAL_AFTER_S``
    after the onset of each arrival; ``flagged`` are the samples where an arrival was first
    flagged (its condition began ``STALL_S`` before)."""
    onset = np.asarray(flagged, dtype=np.int64) - (_STALL_N - 1)
    before = int(round(ARRIVAL_BEFORE_S / SAMPLE_PERIOD_S))
    after = int(round(ARRIVAL_AFTER_S / SAMPLE_PERIOD_S))
    out = np.zeros(n, dtype=bool)
    for i in onset:
        out[max(i - before, 0) : i + after + 1] = True
    return out


def _held(mask: np.ndarray, need: int) -> np.ndarray:
    """True where ``mask`` has been true for the last ``need`` samples."""
    c = np.cumsum(np.concatenate(([0], mask.astype(np.int64))))
    run = np.zeros(mask.size, dtype=bool)
    run[need - 1 :] = (c[need:] - c[:-need]) == need
    return run


def rod_from_flow(
    spool: np.ndarray,
    pp_bar: np.ndarray,
    pa_bar: np.ndarray,
    pb_bar: np.ndarray,
    qp_lpm: np.ndarray,
    machine: MachineParams,
) -> tuple[np.ndarray, np.ndarray]:
    """Rod position (mm) per sample from pump flow, and the samples not to compare (the
    rod's arrivals on a stop, ``arrivals``).  The position is set to the stroke's end
    wherever the recording shows the rod on a stop (``stalls``, ``holds_on_stop``) and
    clipped to the stroke.  Between two stalls the flow is integrated
    forwards from the earlier and backwards from the later one, weighted by how near each
    is (a leak or a flow meter's error drifts the integral apart; it has to arrive at the
    stop when the rod does, or a segment that ends on the stop starts a rod that stalls
    early or runs on); before the first stall backwards only, after the last forwards only
    (from 0 when the recording has no stall: the starting position is unknown)."""
    q = np.nan_to_num(qp_lpm) * LPM
    v = np.where(
        spool > CENTRE_PCT,
        q / machine.cylinder.area_a_m2,
        np.where(spool < -CENTRE_PCT, -q / machine.cylinder.area_b_m2, 0.0),
    )
    stall = stalls(spool, pp_bar, pa_bar, pb_bar, qp_lpm, machine)
    stall = np.where(stall != 0, stall, holds_on_stop(spool, pa_bar, pb_bar, machine))
    stroke = machine.cylinder.stroke_m
    dt = SAMPLE_PERIOD_S
    n = v.size
    ahead, back = np.empty(n), np.empty(n)
    pos = 0.0
    arrived = []
    last, away = 0, True  # the last stop found, and whether the rod has left it since
    for i in range(n):
        if stall[i]:
            if stall[i] != last or away:
                arrived.append(i)
            last, away = int(stall[i]), False
            pos = stroke if stall[i] > 0 else 0.0
        ahead[i] = pos
        pos = min(max(pos + v[i] * dt, 0.0), stroke)
        if last and abs(pos - (stroke if last > 0 else 0.0)) * 1e3 > ARRIVED_MM:
            away = True
    anchored = np.flatnonzero(stall)
    unscored = arrivals(np.array(arrived, dtype=np.int64), n)
    if anchored.size == 0:
        return ahead * 1e3, unscored
    for i in range(n - 1, -1, -1):
        if stall[i]:
            pos = stroke if stall[i] > 0 else 0.0
        elif i > anchored[-1]:
            pos = ahead[i]
        back[i] = pos
        if i > 0:
            pos = min(max(pos - v[i - 1] * dt, 0.0), stroke)
    idx = np.arange(n)
    prev = np.maximum.accumulate(np.where(stall != 0, idx, -1))
    nxt = np.minimum.accumulate(np.where(stall != 0, idx, n)[::-1])[::-1]
    w = np.where(prev < 0, 0.0, np.where(nxt >= n, 1.0, (nxt - idx) / np.maximum(nxt - prev, 1)))
    return (w * ahead + (1.0 - w) * back) * 1e3, unscored
