"""Check that a recording can be diagnosed and put it on a uniform 100 Hz grid.

The gap tool drives the simulator with the recording's own commands, so it refuses, with one
clear line, what it cannot use: missing commands (exit 2), no or too little hydraulic data,
no motion at all, or signals that this machine cannot produce (exit 3, a recording of
another machine or another unit system).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monitor.errors import InputFileError, NoHydraulicDataError
from monitor.gap.data.rodflow import rod_from_flow
from monitor.io.recording import Recording
from monitor.signals import COMMAND_NAMES, MEASURED_NAMES, SAMPLE_PERIOD_S
from monitor.sim.effects import SENSOR_CAL_SIGNALS
from monitor.sim.machine import BAR, LPM, MachineParams

#: Shortest recording worth diagnosing: calibration and held-out parts need a few duty
#: cycles each.
MIN_DURATION_S = 40.0
#: A row gap longer than this is missing data (the CSV contract: more than 3 periods).
MAX_GAP_S = 3.5 * SAMPLE_PERIOD_S
#: Share of finite samples a measured signal needs.
MIN_VALID_SHARE = 0.8
#: Measured flow or pressure this far above what the configured machine can deliver means
#: another machine (or other units): the simulator cannot be compared with it.
PLAUSIBLE_MARGIN = 1.3
#: Measured pressure (bar) or flow (L/min) at or below this may be a sensor clipping at
#: zero, as the contract's sensors do (a drained chamber, a dead-headed pump) ...
ZERO_MARGIN = 1.0
#: ... unless this share of the signal's samples reads below ``-ZERO_MARGIN``: then its
#: sensor reads below zero (the other team's flow sensor with a -3.3 L/min offset read
#: that at rest, where ours would read 0), far more often than its noise would (1 %: a
#: zero-mean noise of up to 0.4 of the margin stays above it).
BELOW_ZERO_SHARE = 0.01


@dataclass
class Prepared:
    """A recording on a uniform grid, ready for segment-wise simulation.

    ``meas`` holds PP, PA, PB (bar) and QP (L/min) with NaN for missing samples, plus the
    rod velocity ``RodVel`` (mm/s) when RodPos is measured; ``cmd``
    the four commands (finite everywhere ``valid`` is true); ``rod_mm`` the rod position
    (measured RodPos, lightly smoothed, or integrated from pump flow when absent);
    ``scale`` the measured standard deviation per signal and ``noise_var`` the sensor
    noise variance per signal, both in the signal's units.
    """

    t: np.ndarray
    cmd: dict[str, np.ndarray]
    meas: dict[str, np.ndarray]
    valid: np.ndarray
    rod_mm: np.ndarray
    has_rodpos: bool
    scale: dict[str, float]
    noise_var: dict[str, float]
    source: str
    stroke_mm: float
    #: Samples not compared (``score.normalised`` leaves them out): without RodPos, the
    #: moments the rod arrives on an end stop (``rodflow.arrivals``).  None: every sample.
    unscored: np.ndarray | None = None
    #: Signals whose sensor reads below zero in this recording (``reads_below_zero``).
    below_zero: frozenset[str] = frozenset()
    #: RodPos measured by a sensor whose reading shows a clip at zero (``rod_clips``).
    rod_clips: bool = False

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def reading(self, name: str, values: np.ndarray) -> np.ndarray:
        """Simulated values of ``name`` as its sensor shows them after a gain or offset:
        clipped at zero, unless it reads below zero in this recording."""
        return values if name in self.below_zero else np.maximum(values, 0.0)

    def off_zero(self, name: str, measured: np.ndarray) -> np.ndarray:
        """Rows where ``measured`` (of ``name``) cannot be its sensor clipping at zero:
        every finite row of a sensor that reads below zero, else those above
        ``ZERO_MARGIN``."""
        if name in self.below_zero:
            return np.isfinite(measured)
        return measured > ZERO_MARGIN


def reads_below_zero(meas: dict[str, np.ndarray]) -> frozenset[str]:
    """The signals in ``meas`` whose readings go below ``-ZERO_MARGIN`` in at least
    ``BELOW_ZERO_SHARE`` of their samples."""
    return frozenset(
        n for n, v in meas.items() if np.mean(v[np.isfinite(v)] < -ZERO_MARGIN) >= BELOW_ZERO_SHARE
    )


def rod_clips(rod_mm: np.ndarray) -> bool:
    """Whether a RodPos reading shows a sensor that clips at zero: never below it, and at
    exactly zero in at least ``BELOW_ZERO_SHARE`` of the samples (a rod resting on its stop
    reads noise around zero on a sensor that does not clip).  Such a sensor hides how far a
    rod read 0 is above its end stop: ``predict.py`` reads the starts and the simulated rod
    through the clip."""
    rod = rod_mm[np.isfinite(rod_mm)]
    return bool(rod.size) and bool(rod.min() >= 0.0 and np.mean(rod == 0.0) >= BELOW_ZERO_SHARE)


def _resample(rec: Recording) -> tuple[np.ndarray, dict[str, np.ndarray], np.ndarray]:
    """Columns on t0 + k * 10 ms; grid points inside a gap of missing rows become NaN."""
    t = rec.t
    n = int(np.floor((t[-1] - t[0]) / SAMPLE_PERIOD_S + 1e-6)) + 1
    grid = t[0] + np.arange(n) * SAMPLE_PERIOD_S
    if len(t) == n and np.allclose(t, grid, atol=1e-6):
        return grid, {k: v.copy() for k, v in rec.columns.items()}, np.ones(n, bool)
    right = np.clip(np.searchsorted(t, grid), 1, len(t) - 1)
    in_gap = (t[right] - t[right - 1]) > MAX_GAP_S
    cols = {}
    for name, values in rec.columns.items():
        ok = np.isfinite(values)
        out = np.full(n, np.nan)
        if ok.sum() >= 2:
            out = np.interp(grid, t[ok], values[ok])
            # A sample missing in the file stays missing on the grid.
            near = np.abs(t[right] - grid) < np.abs(t[right - 1] - grid)
            idx = np.where(near, right, right - 1)
            out[~ok[idx]] = np.nan
        out[in_gap] = np.nan
        cols[name] = out
    return grid, cols, ~in_gap


def noise_variance(x: np.ndarray) -> float:
    """White-noise variance from the second difference (var = 6 sigma^2), robust to motion."""
    d2 = x[2:] - 2.0 * x[1:-1] + x[:-2]
    # Near zero a sensor that clips there hides half of its noise.
    away = (x[:-2] > ZERO_MARGIN) & (x[1:-1] > ZERO_MARGIN) & (x[2:] > ZERO_MARGIN)
    d2 = d2[np.isfinite(d2) & away]
    if d2.size < 10:
        return 0.0
    mad = np.median(np.abs(d2 - np.median(d2)))
    return float((1.4826 * mad) ** 2 / 6.0)


#: The measured rod velocity (mm/s), compared as a fifth signal when RodPos is measured: it
#: tells a slow spool (the rod moves late too) from a lag of the pressure and flow sensors
#: (the rod moves on time), which look alike in PP, PA, PB and QP.
ROD_VEL = "RodVel"
_SMOOTH = np.ones(5) / 5


def smooth_rod(rod_mm: np.ndarray) -> np.ndarray:
    """Five-sample moving average (edges held): takes the 0.5 mm sensor noise down."""
    return np.convolve(np.pad(rod_mm, 2, mode="edge"), _SMOOTH, mode="valid")


#: Half span of the rod velocity's difference (samples): the velocity of a noisy RodPos is
#: noise-dominated over 2 samples (10 mm/s rms against ~100 mm/s of motion); over +-5 it
#: is 10x quieter and still shows a spool's delay of tens of milliseconds.
ROD_VEL_HALF_SPAN = 5


def rod_velocity(rod_mm: np.ndarray) -> np.ndarray:
    """Velocity (mm/s) of a smoothed rod position, (x[i+k] - x[i-k]) / 2k dt, edges held."""
    k = ROD_VEL_HALF_SPAN
    x = np.pad(rod_mm, k, mode="edge")
    return (x[2 * k :] - x[: -2 * k]) / (2 * k * SAMPLE_PERIOD_S)


_DIFF = np.zeros(2 * ROD_VEL_HALF_SPAN + 1)
_DIFF[[0, -1]] = np.array([1.0, -1.0]) / (2 * ROD_VEL_HALF_SPAN * SAMPLE_PERIOD_S)
#: White noise of variance s2 on RodPos leaves s2 * this on ``rod_velocity(smooth_rod(.))``
#: (the sum of the squared taps of the moving average followed by the difference).
ROD_VEL_NOISE_GAIN = float(np.sum(np.convolve(_SMOOTH, _DIFF) ** 2))


def prepare(rec: Recording, machine: MachineParams) -> Prepared:
    """Validate ``rec`` for the gap tool and resample it; raises a ``MonitorError``."""
    src = rec.source
    _check_signals(rec)
    t, cols, valid = _resample(rec)
    valid = _check_samples(src, cols, valid)
    spool = np.nan_to_num(cols["SpoolCmd"])
    if not (np.abs(spool) > 5.0).any():
        raise NoHydraulicDataError(
            f"{src}: SpoolCmd never leaves centre: nothing moves, no dynamics to compare"
        )
    _check_plausible(src, cols, machine)
    meas = {n: cols[n] for n in MEASURED_NAMES}
    unscored = None
    has_rod = rec.has("RodPos") and np.isfinite(cols["RodPos"]).mean() >= MIN_VALID_SHARE
    if has_rod:
        rod = cols["RodPos"]
        ok = np.isfinite(rod)
        rod = smooth_rod(np.interp(t, t[ok], rod[ok]))
    else:
        pressures = (meas["PP"], meas["PA"], meas["PB"], meas["QP"])
        rod, unscored = rod_from_flow(spool, *pressures, machine)
    scale = {n: float(np.nanstd(v)) for n, v in meas.items()}
    for name, s in scale.items():
        if not s > 0:
            raise NoHydraulicDataError(f"{src}: {name} is constant: no hydraulic activity")
    noise_var = {n: noise_variance(v) for n, v in meas.items()}
    if has_rod and float(np.std(rod_velocity(rod))) > 0:
        meas[ROD_VEL] = rod_velocity(rod)
        scale[ROD_VEL] = float(np.std(meas[ROD_VEL]))
        noise_var[ROD_VEL] = noise_variance(cols["RodPos"]) * ROD_VEL_NOISE_GAIN
    return Prepared(
        t=t,
        cmd={n: np.nan_to_num(cols[n]) for n in COMMAND_NAMES},
        meas=meas,
        valid=valid,
        rod_mm=rod,
        has_rodpos=bool(has_rod),
        scale=scale,
        noise_var=noise_var,
        source=src,
        stroke_mm=machine.cylinder.stroke_m * 1e3,
        unscored=unscored,
        below_zero=reads_below_zero({n: meas[n] for n in MEASURED_NAMES}),
        rod_clips=bool(has_rod) and rod_clips(cols["RodPos"]),
    )


def _check_signals(rec: Recording) -> None:
    """The commands and the hydraulic signals present, and the recording long enough."""
    src = rec.source
    missing_cmd = [n for n in COMMAND_NAMES if not rec.has(n)]
    if missing_cmd:
        raise InputFileError(
            f"{src}: command signal(s) {', '.join(missing_cmd)} missing: the simulator is "
            "driven by the recording's own commands"
        )
    present = [n for n in MEASURED_NAMES if rec.has(n)]
    if len(present) < len(MEASURED_NAMES):
        others = ", ".join(n for n in rec.columns if n not in COMMAND_NAMES) or "none"
        raise NoHydraulicDataError(
            f"{src}: no usable hydraulic data: needs {', '.join(MEASURED_NAMES)}, has {others}"
        )
    if len(rec) < 2 or rec.t[-1] - rec.t[0] < MIN_DURATION_S:
        dur = 0.0 if len(rec) < 2 else rec.t[-1] - rec.t[0]
        raise NoHydraulicDataError(
            f"{src}: {dur:.1f} s is too short to diagnose: needs at least {MIN_DURATION_S:g} s "
            "(a calibration and a held-out part of several duty cycles)"
        )


def _check_samples(src: str, cols: dict[str, np.ndarray], valid: np.ndarray) -> np.ndarray:
    """Every command and measured signal present in enough of the resampled samples; the
    samples valid where every command is."""
    for name in COMMAND_NAMES:
        ok = np.isfinite(cols[name])
        if ok.mean() < MIN_VALID_SHARE:
            raise InputFileError(
                f"{src}: command {name} is missing in {100 * (1 - ok.mean()):.0f} % of the "
                "samples; the simulator needs the commands"
            )
        valid &= ok
    for name in MEASURED_NAMES:
        share = float(np.isfinite(cols[name]).mean())
        if share < MIN_VALID_SHARE:
            raise NoHydraulicDataError(
                f"{src}: {name} is missing in {100 * (1 - share):.0f} % of the samples"
            )
    return valid


def _check_plausible(src: str, cols: dict[str, np.ndarray], machine: MachineParams) -> None:
    speed = np.nanpercentile(cols["EngineSpeed"], 99)
    q_max = machine.pump.pump_disp_m3_rev * max(speed, 1.0) / 60.0 / LPM
    q99 = np.nanpercentile(cols["QP"], 99)
    if q99 > PLAUSIBLE_MARGIN * q_max:
        raise NoHydraulicDataError(
            f"{src}: QP reaches {q99:.1f} L/min but the configured pump delivers at most "
            f"{q_max:.1f} L/min at {speed:.0f} rpm: a recording of another machine? "
            "(pass its simulator config with --config)"
        )
    p_max = machine.line.relief_full_pa / BAR
    for name in ("PP", "PA", "PB"):
        p99 = np.nanpercentile(cols[name], 99)
        # Below zero by up to the largest sensor offset the diagnosis can name (plus noise):
        # a transducer reading -12 bar at rest is what `sensor_calibration` is for.
        p_min = -(SENSOR_CAL_SIGNALS[name].max_offset + 5.0)
        if p99 > PLAUSIBLE_MARGIN * p_max or np.nanpercentile(cols[name], 1) < p_min:
            raise NoHydraulicDataError(
                f"{src}: {name} spans {np.nanpercentile(cols[name], 1):.1f}..{p99:.1f} bar, "
                f"outside what a loop with relief at {p_max:.0f} bar can show: another "
                "machine or other units? (pass its simulator config with --config)"
            )
