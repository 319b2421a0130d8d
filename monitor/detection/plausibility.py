"""Sensor plausibility beyond staleness: named sensor faults, each with the signal it concerns.

Checks (``plausibility:`` in config/monitor.yaml; times in seconds of 100 Hz samples):

* ``signal_range``: a signal outside the sensor's range (the DBC ranges by default; the
  pressure and flow limits are configurable) for ``range_s``.  On the bus the decoder already
  rejects a frame whose value lies outside the DBC range (the signal then goes stale: the
  DBC's range stays the decoder's hard limit); this names the signal for CSV input, for a
  DBC wider than the sensor (signed pressures) and for configured limits tighter than the
  DBC's.  The transducers PP, PA, PB and QP get a field tolerance at the low end: a 4-20 mA
  transducer sits up to +-0.5 % of full scale off zero and its noise crosses zero, and zero
  (tank pressure, no flow) is where the loop rests, so a healthy sensor reads down to
  ``range_tolerance_fs`` of full scale below its lower limit (1 %: 4 bar on 0..400 bar,
  0.6 L/min on 0..60 L/min).  Full scale is never an operating point (the relief valve
  sits well below it), so a transducer reading at its upper limit or above is saturated,
  pinned there (a short to supply, an over-range): out of range.  Commands, EngineSpeed and
  OilTemp keep their limits exactly (a full spool command is normal).
* ``frozen``: PP, PA, PB or QP repeat the very same value for ``frozen_s`` while the engine
  runs: a live sensor always shows noise (0.3 bar / 0.1 L/min rms on the reference machine,
  far above the 0.01 resolution), so a variance of exactly zero is a frozen filter or a
  hung sensor node that still sends frames.  A reading at its range limit is saturated and
  may legitimately repeat, so it does not count, except QP at 0 L/min while the valve
  passes oil: the spool open by ``relation_spool_pct`` or more and PP more than
  ``relation_margin_bar`` above the port it feeds (A for a positive command, B for a
  negative).  An open metering edge with that pressure drop across it has flow through it,
  so a flow reading pinned at zero there is a frozen sensor (a flow meter reads exactly 0
  only without flow, e.g. at an end stop, where the fed port rises to PP).
* ``stuck``: PP, PA, PB or QP stay within +-``stuck_band_bar`` (``stuck_band_lpm``) of one
  value while the machine moves (|SpoolCmd| >= ``move_spool_pct`` or QP >=
  ``move_flow_lpm``) for ``stuck_s`` of moving time in total: a sensor whose noise is alive
  but which no longer follows the loop.
* ``pump_below_port``: while the spool is open (|SpoolCmd| >= ``relation_spool_pct``) the
  pump feeds the ports through the valve, so PP >= max(PA, PB) - ``relation_margin_bar``.
  A port above PP for ``relation_s``: an offset or drift.  The sensor named is that port;
  once both ports have been seen above PP (a low-reading PP shows against whichever port
  is fed, a high-reading port only against itself) it is PP, the common factor.  Holding
  proves little (an offset hides while the valve drop exceeds it), so the finding stays
  until a rest (below) reads the port at tank.
* ``rest_offset``: with the engine off (a reading below ``alarm.min_engine_rpm``) and
  |SpoolCmd| below ``move_spool_pct`` for ``rest_settle_s``, the pump has stopped and the
  lines have bled to tank through the pump and the spool's clearances: PP and PB (the rod
  side, the tank side of a held gravity load) further than ``rest_max_bar`` from 0 bar gauge
  is an offset.  PA is not judged at rest: a boom parked in the air keeps its load pressure
  trapped in the cap side, which is normal; PA reading tank at rest still clears an earlier
  finding on it.  (``rest_settle_s: 0`` switches the check off.)

On a load-sensing machine (``pump_system: load_sensing``) the pump is shared: it stands
``ls_margin_bar`` above the highest load pressure of the open sections, at standby when all
are closed.  Two rules change there, both because of what a shared pump makes normal:
``pump_below_port`` judges only the port the pump feeds (A for a positive command, B for a
negative): the other port meters a held load out to tank, and a lowered boom's cap side may
stand far above a pump that serves a lighter function.  And QP at 0 L/min counts as frozen
only across a drop above ``relation_margin_bar`` plus the margin: a stalled section (on its
stop, or against a load the pump cannot lift) has the pump its margin above its port and no
flow.  The single loop on its own compensated pump (``pressure_compensated``, the default)
keeps the rules above.

A finding latches until its own check shows the sensor healthy again (range: back in range;
frozen/stuck: the value moves; the relation and rest offsets: a later rest reads the
sensor near tank), so an offset found at key-off is still named when the engine starts.
While any finding is active the sample counts as a sensor fault (MON_Alarm.State 2, the
residual not used); events name the first finding in check order, then signal order.

One numba kernel runs the checks over any number of rows with its state in arrays: offline
over a whole recording in one call, live over one row per tick, so both give the same
findings sample by sample, and a tick allocates nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monitor.detection.plausibility_config import COLUMNS, PlausibilityConfig
from monitor.detection.plausibility_config import DBC_RANGES as DBC_RANGES
from monitor.jit import jit
from monitor.signals import SAMPLE_PERIOD_S

#: Check names by code (code 0 = no finding); the order is the reporting priority.
CHECKS: tuple[str, ...] = ("signal_range", "frozen", "stuck", "pump_below_port", "rest_offset")
_SPOOL, _ENGINE, _PP, _PA, _PB, _QP = (
    COLUMNS.index(n) for n in ("SpoolCmd", "EngineSpeed", "PP", "PA", "PB", "QP")
)


# Indices of the kernel's parameter vector (``kernel_params``): numba takes one
# float array, and names keep its order from drifting between the two sides.
(
    P_RANGE_N,
    P_FROZEN_N,
    P_STUCK_N,
    P_BAND_BAR,
    P_BAND_LPM,
    P_MOVE_SPOOL,
    P_MOVE_FLOW,
    P_REL_SPOOL,
    P_REL_MARGIN,
    P_REL_N,
    P_REST_N,
    P_REST_MAX,
    P_LS_MARGIN,
) = range(13)
N_PARAMS = 13


def kernel_params(cfg: PlausibilityConfig) -> np.ndarray:
    """Kernel parameters at the ``P_*`` indices; times as sample counts (0: check off)."""
    n = lambda s: float(round(s / SAMPLE_PERIOD_S))  # noqa: E731
    p = np.zeros(N_PARAMS)
    p[P_RANGE_N], p[P_FROZEN_N] = n(cfg.signal_range.range_s), n(cfg.frozen.frozen_s)
    p[P_STUCK_N] = n(cfg.stuck.stuck_s)
    p[P_BAND_BAR], p[P_BAND_LPM] = cfg.stuck.stuck_band_bar, cfg.stuck.stuck_band_lpm
    p[P_MOVE_SPOOL], p[P_MOVE_FLOW] = cfg.motion.move_spool_pct, cfg.motion.move_flow_lpm
    p[P_REL_SPOOL], p[P_REL_MARGIN] = (
        cfg.relation.relation_spool_pct,
        cfg.relation.relation_margin_bar,
    )
    p[P_REL_N], p[P_REST_N] = n(cfg.relation.relation_s), n(cfg.rest.rest_settle_s)
    p[P_REST_MAX] = cfg.rest.rest_max_bar
    # 0: a pressure-compensated pump of its own; > 0: a load-sensing pump's margin.
    p[P_LS_MARGIN] = cfg.pump.ls_margin_bar if cfg.pump.load_sensing else 0.0
    return p


# State arrays (per column): counters[0] range run, [1] identical run, [2] stuck moving
# samples, [3] relation run per port (violating samples);
# ref[c] stuck reference, last[c] previous value; active[check, column] latched findings;
# misc[0] rest run (engine off, spool centred).
@jit(aot=True)
def _run(  # pragma: no cover - numba
    x, cols, lo, hi, rlo, rhi, p, counters, ref, last, active, misc, min_rpm, out_check, out_sig
):
    # x[i, cols[c]] is column c (COLUMNS order) of sample i; lo/hi the sensor range (frozen
    # check), rlo/rhi the readings in range (``range_limits``).
    n, m = x.shape[0], cols.shape[0]
    range_n, frozen_n, stuck_n = p[P_RANGE_N], p[P_FROZEN_N], p[P_STUCK_N]
    band_bar, band_lpm = p[P_BAND_BAR], p[P_BAND_LPM]
    move_spool, move_flow = p[P_MOVE_SPOOL], p[P_MOVE_FLOW]
    rel_spool, rel_margin, rel_n = p[P_REL_SPOOL], p[P_REL_MARGIN], p[P_REL_N]
    rest_n, rest_max = p[P_REST_N], p[P_REST_MAX]
    ls_margin = p[P_LS_MARGIN]
    load_sensing = ls_margin > 0.0
    for i in range(n):
        spool = x[i, cols[_SPOOL]]
        engine = x[i, cols[_ENGINE]]
        running = engine >= min_rpm
        qp = x[i, cols[_QP]]
        moving = running and (abs(spool) >= move_spool or qp >= move_flow)
        # The valve passes oil: open, with the pump well above the port it feeds (False
        # when a pressure is NaN).  A load-sensing pump holds its margin over a stalled
        # section too, so there only a drop beyond the margin proves flow.
        fed_c = _PA if spool > 0 else _PB
        fed = x[i, cols[fed_c]]
        passing = (
            running and abs(spool) >= rel_spool and x[i, cols[_PP]] - fed > rel_margin + ls_margin
        )
        for c in range(m):
            v = x[i, cols[c]]
            if np.isnan(v):
                continue  # staleness is the sampler's verdict; no evidence either way
            # signal_range
            if v < rlo[c] or v > rhi[c]:
                counters[0, c] += 1
                if range_n > 0 and counters[0, c] >= range_n:
                    active[0, c] = True
            else:
                counters[0, c] = 0
                active[0, c] = False
            if c < _PP:
                last[c] = v
                continue  # commands and oil temperature: range only
            # frozen
            if (
                v == last[c]
                and running
                and (lo[c] < v < hi[c] or (c == _QP and v == lo[c] and passing))
            ):
                counters[1, c] += 1
                if frozen_n > 0 and counters[1, c] >= frozen_n:
                    active[1, c] = True
            elif v != last[c]:
                counters[1, c] = 0
                active[1, c] = False
            last[c] = v
            # stuck
            band = band_lpm if c == _QP else band_bar
            if abs(v - ref[c]) > band or np.isnan(ref[c]):
                ref[c] = v
                counters[2, c] = 0
                active[2, c] = False
            elif moving:
                counters[2, c] += 1
                if stuck_n > 0 and counters[2, c] >= stuck_n:
                    active[2, c] = True
        # pump_below_port: PP >= max(PA, PB) - margin while the spool is open; a run of
        # violating samples per port.  A healthy port never reads above the pump that feeds
        # it, but a port reading high hides whenever the valve drop exceeds its offset, so
        # holding proves little: the finding latches until a rest reads the port at tank.
        pp = x[i, cols[_PP]]
        if running and abs(spool) >= rel_spool and rel_n > 0 and not np.isnan(pp):
            for c in (_PA, _PB):
                if load_sensing and c != fed_c:
                    # The port draining to tank: on a load-sensing machine the pump serves
                    # the lightest work, and the held load's side may be far above it.
                    continue
                v = x[i, cols[c]]
                if v > pp + rel_margin:
                    counters[3, c] += 1
                    if counters[3, c] >= rel_n:
                        active[3, c] = True
                elif not np.isnan(v):
                    counters[3, c] = 0
        # Both ports above the pump: the common factor, PP reading low, is the one named.
        active[3, _PP] = active[3, _PA] and active[3, _PB]
        # rest_offset: engine off, spool centred, settled -> pressures near tank
        if (not np.isnan(engine)) and (not running) and abs(spool) < move_spool and rest_n > 0:
            misc[0] += 1
            if misc[0] >= rest_n:
                for c in range(_PP, _PB + 1):
                    v = x[i, cols[c]]
                    if not np.isnan(v):
                        # PA may hold a parked boom's load: judged only when it reads tank.
                        active[4, c] = abs(v) > rest_max and c != _PA
                        if abs(v) <= rest_max:
                            active[3, c] = False  # read at tank: no offset after all
        else:
            misc[0] = 0
        out_check[i] = 0
        out_sig[i] = -1
        for k in range(active.shape[0]):
            for c in range(m):
                if active[k, c]:
                    out_check[i] = k + 1
                    out_sig[i] = c
                    break
            if out_check[i] != 0:
                break


@dataclass(frozen=True)
class _Limits:
    """The kernel's fixed inputs from the config: sensor range, readings in range, params."""

    lo: np.ndarray
    hi: np.ndarray
    rlo: np.ndarray
    rhi: np.ndarray
    params: np.ndarray

    @classmethod
    def of(cls, cfg: PlausibilityConfig) -> _Limits:
        return cls(*cfg.limits(), *cfg.range_limits(), kernel_params(cfg))


class _CheckState:
    """The kernel's state arrays (see ``_run``), carried from one call to the next."""

    def __init__(self, m: int) -> None:
        self.counters = np.zeros((4, m), dtype=np.int64)
        self.ref = np.full(m, np.nan)
        self.last = np.full(m, np.nan)
        self.active = np.zeros((len(CHECKS), m), dtype=np.bool_)
        self.misc = np.zeros(1, dtype=np.int64)


class Plausibility:
    """The checks with their state; ``series`` and ``step`` continue the same state."""

    def __init__(self, cfg: PlausibilityConfig, min_engine_rpm: float) -> None:
        self.cfg = cfg
        self.min_engine_rpm = float(min_engine_rpm)
        self._limits = _Limits.of(cfg)
        self._state = _CheckState(len(COLUMNS))
        self._check1 = np.zeros(1, dtype=np.int8)
        self._sig1 = np.zeros(1, dtype=np.int8)
        self.check = 0  # last sample's finding: check code (0 none) and column index
        self.signal = -1

    def series(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(samples, COLUMNS) -> (check code, column index) per sample."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        check = np.zeros(x.shape[0], dtype=np.int8)
        sig = np.zeros(x.shape[0], dtype=np.int8)
        self._kernel(x, np.arange(len(COLUMNS), dtype=np.int64), check, sig)
        if len(check):
            self.check, self.signal = int(check[-1]), int(sig[-1])
        return check, sig

    def step(self, x1: np.ndarray, cols: np.ndarray) -> int:
        """One sample: ``x1[0, cols[c]]`` is column c (int64 ``cols``); returns the check
        code (0: none)."""
        self._kernel(x1, cols, self._check1, self._sig1)
        self.check, self.signal = int(self._check1[0]), int(self._sig1[0])
        return self.check

    def _kernel(self, x: np.ndarray, cols: np.ndarray, check: np.ndarray, sig: np.ndarray) -> None:
        lim, st = self._limits, self._state
        _run(
            x,
            cols,
            lim.lo,
            lim.hi,
            lim.rlo,
            lim.rhi,
            lim.params,
            st.counters,
            st.ref,
            st.last,
            st.active,
            st.misc,
            self.min_engine_rpm,
            check,
            sig,
        )


#: The gate's finding after the kernel's checks (``monitor.detection.gating``): EngineSpeed
#: missing while the pump shows a working machine (``opstate.silent_source``).
STALE = len(CHECKS) + 1
_NAMES = (*CHECKS, "stale")


def finding(check: int, signal: int) -> tuple[str | None, str | None]:
    """(sensor, check name) of a finding code, (None, None) for none."""
    if check <= 0:
        return None, None
    return COLUMNS[signal], _NAMES[check - 1]
