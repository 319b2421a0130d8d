"""Run the boom loop: commands in, 100 Hz contract signals (and internal states) out."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from monitor.errors import ConfigError
from monitor.io.recording import Recording
from monitor.signals import COMMAND_NAMES
from monitor.sim import kernel as K
from monitor.sim.effects import Effect
from monitor.sim.faults import Fault
from monitor.sim.machine import MachineParams
from monitor.sim.pack import pack_inputs, pack_params, rest_state
from monitor.sim.sensors import SensorParams, lag, measure, quantise, sample_hold

#: The plant record runs at 1 kHz: fine enough for sensor lag, cheap to keep.
RECORD_PERIOD_S = 1e-3
PA_PER_BAR = 1e5
M3S_PER_LPM = 1e-3 / 60.0


@dataclass
class PlantTrace:
    """True plant values (SI) at the record rate."""

    t_s: np.ndarray
    pp_pa: np.ndarray
    pa_pa: np.ndarray
    pb_pa: np.ndarray
    qp_m3_s: np.ndarray
    rod_pos_m: np.ndarray
    rod_vel_m_s: np.ndarray
    spool: np.ndarray  # effective spool position, fraction of full stroke


def check_commands(commands: Recording) -> None:
    """Raise ConfigError unless the commands are all there, finite and on a uniform axis."""
    commands.require(COMMAND_NAMES)
    if len(commands) < 2:
        raise ConfigError(f"{commands.source}: need at least two command samples")
    dt = np.diff(commands.t)
    if not np.allclose(dt, dt[0], rtol=1e-6, atol=1e-9) or dt[0] <= 0:
        raise ConfigError(f"{commands.source}: commands must be on a uniform, increasing time axis")
    for name in COMMAND_NAMES:
        if not np.all(np.isfinite(commands[name])):
            raise ConfigError(
                f"{commands.source}: command {name} has missing or non-finite samples"
            )


def run_plant(
    commands: Recording,
    machine: MachineParams,
    faults: list[Fault] | tuple[Fault, ...] = (),
    effects: list[Effect] | tuple[Effect, ...] = (),
    rod_pos0_m: float = 0.1,
    record_period_s: float | None = RECORD_PERIOD_S,
    state0: np.ndarray | None = None,
    corrections: Mapping[str, float] | None = None,
) -> PlantTrace:
    """Integrate the plant driven by ``commands``; ``record_period_s=None`` records every step.

    The plant starts at rest at ``rod_pos0_m``, or from ``state0`` (a kernel state vector,
    e.g. ``pack.measured_state``) to simulate a segment of a recording from its measured
    state.
    """
    check_commands(commands)
    input_dt = float(commands.t[1] - commands.t[0])
    prm = pack_params(machine, effects, corrections)
    u = pack_inputs(
        commands.t,
        commands["SpoolCmd"],
        commands["PumpDispCmd"],
        commands["EngineSpeed"],
        commands["OilTemp"],
        faults,
        effects,
    )
    if state0 is None:
        y0 = rest_state(machine, prm, rod_pos0_m)
    else:
        y0 = np.asarray(state0, dtype=np.float64)
        if y0.shape != (K.N_STATES,):
            raise ConfigError(f"state0 must have {K.N_STATES} values, got {y0.shape}")
    return run_packed(
        float(commands.t[0]), input_dt, u, prm, y0, machine.solver.step_s, record_period_s
    )


def run_packed(
    t0_s: float,
    input_dt: float,
    inputs: np.ndarray,
    prm: np.ndarray,
    y0: np.ndarray,
    step_s: float,
    record_period_s: float | None = RECORD_PERIOD_S,
) -> PlantTrace:
    """``run_plant`` on inputs already packed (``pack_inputs``, a uniform axis from ``t0_s``
    every ``input_dt``) and a parameter vector (``pack_params``): for callers that run the
    same commands many times (the sim-to-real fits), with no checks repeated."""
    n_sub = max(1, int(round(input_dt / step_s)))
    h = input_dt / n_sub
    every = 1 if record_period_s is None else max(1, int(round(record_period_s / h)))
    rec = K.integrate(y0, inputs, n_sub, input_dt, prm, every)
    t = t0_s + np.arange(rec.shape[0]) * (h * every)
    return PlantTrace(
        t,
        rec[:, K.R_PP],
        rec[:, K.R_PA],
        rec[:, K.R_PB],
        rec[:, K.R_QP],
        rec[:, K.R_X],
        rec[:, K.R_V],
        rec[:, K.R_XS],
    )


def simulate(
    commands: Recording,
    machine: MachineParams,
    faults: list[Fault] | tuple[Fault, ...] = (),
    effects: list[Effect] | tuple[Effect, ...] = (),
    seed: int | None = 0,
    rod_pos0_m: float = 0.1,
    sensors: SensorParams | None = None,
    corrections: Mapping[str, float] | None = None,
) -> Recording:
    """Contract signals at the commands' sample times; ``seed=None`` gives noise-free output.

    Columns: the commands (quantised as on the bus), PP, PA, PB (bar), QP (L/min), RodPos
    (mm), plus the true internal states SpoolPos (%), RodPosTrue (mm) and RodVel (mm/s).
    """
    names = [e.name for e in effects]
    if len(set(names)) != len(names):
        raise ConfigError(f"an effect is given twice: {', '.join(names)}")
    trace = run_plant(commands, machine, faults, effects, rod_pos0_m, corrections=corrections)
    return sense(commands, trace, machine, faults, effects, seed, sensors)


def sense(
    commands: Recording,
    trace: PlantTrace,
    machine: MachineParams,
    faults: list[Fault] | tuple[Fault, ...] = (),
    effects: list[Effect] | tuple[Effect, ...] = (),
    seed: int | None = 0,
    sensors: SensorParams | None = None,
) -> Recording:
    """The contract signals of a plant trace (``simulate``'s second half): one plant run can
    be read with noise (``seed``) and without (``None``), e.g. for a noise-free twin."""
    sensors = sensors or SensorParams()
    rng = np.random.default_rng(seed) if seed is not None else None
    out = _command_readings(commands, sensors)
    out.update(_plant_readings(commands.t, trace, _SensorEffects.of(effects), sensors, rng))
    meta: dict[str, object] = {
        "faults": [f.__dict__ for f in faults],
        "effects": {e.name: {**e.labels, **e.params} for e in effects},
        "seed": seed,
        "step_s": machine.solver.step_s,
    }
    return Recording(commands.t.copy(), out, source=f"simulation of {commands.source}", meta=meta)


@dataclass(frozen=True)
class _SensorEffects:
    """What the sensor effects do to the readings: a lag, and a gain and offset per signal."""

    delay_s: float = 0.0
    time_constant_s: float = 0.0
    calibration: Mapping[str, tuple[float, float]] = field(default_factory=dict)

    @classmethod
    def of(cls, effects: list[Effect] | tuple[Effect, ...]) -> _SensorEffects:
        delay_s = tau_s = 0.0
        cal: dict[str, tuple[float, float]] = {}  # signal: (gain, offset in its unit)
        for effect in effects:
            if effect.name == "sensor_lag":
                delay_s = effect.params["delay_ms"] * 1e-3
                tau_s = effect.params["time_constant_ms"] * 1e-3
            elif effect.name == "sensor_calibration":
                cal[effect.labels["signal"]] = (effect.params["gain"], effect.params["offset"])
        return cls(delay_s, tau_s, cal)

    def reading(self, name: str, values: np.ndarray) -> np.ndarray:
        # The transducer's gain and offset act on what it senses; its noise, range and the
        # bus's quantisation come after (a miscalibrated sensor still clips at its range).
        if name not in self.calibration:
            return values
        gain, offset = self.calibration[name]
        return gain * values + offset


def _command_readings(commands: Recording, s: SensorParams) -> dict[str, np.ndarray]:
    """The commands as the bus carries them (OilTemp held between its slow samples)."""
    t = commands.t
    out: dict[str, np.ndarray] = {}
    for name in ("SpoolCmd", "PumpDispCmd", "EngineSpeed"):
        out[name] = quantise(name, commands[name])
    out["OilTemp"] = quantise(
        "OilTemp", sample_hold(t - t[0], commands["OilTemp"], s.oil_temp_period_s)
    )
    return out


def _plant_readings(
    t: np.ndarray,
    trace: PlantTrace,
    fx: _SensorEffects,
    s: SensorParams,
    rng: np.random.Generator | None,
) -> dict[str, np.ndarray]:
    """The measured signals (PP, PA, PB, QP, RodPos, drawing noise in that order) and the
    true internal states, at the sample times ``t``."""
    rel = trace.t_s - trace.t_s[0]
    idx = np.minimum(np.round((t - t[0]) / (rel[1] - rel[0])).astype(int), len(rel) - 1)

    def sampled(values: np.ndarray, lagged: bool) -> np.ndarray:
        if lagged:
            values = lag(rel, values, fx.delay_s, fx.time_constant_s)
        return values[idx]

    out: dict[str, np.ndarray] = {}
    for name, values in (("PP", trace.pp_pa), ("PA", trace.pa_pa), ("PB", trace.pb_pa)):
        out[name] = measure(
            name,
            fx.reading(name, sampled(values, True) / PA_PER_BAR),
            s.pressure_noise_bar,
            s.pressure_range_bar,
            rng,
        )
    out["QP"] = measure(
        "QP",
        fx.reading("QP", sampled(trace.qp_m3_s, True) / M3S_PER_LPM),
        s.flow_noise_lpm,
        s.flow_range_lpm,
        rng,
    )
    rod_mm = sampled(trace.rod_pos_m, False) * 1e3
    out["RodPos"] = measure(
        "RodPos", fx.reading("RodPos", rod_mm), s.rodpos_noise_mm, s.rodpos_range_mm, rng
    )
    out["SpoolPos"] = sampled(trace.spool, False) * 100.0
    out["RodPosTrue"] = rod_mm
    out["RodVel"] = sampled(trace.rod_vel_m_s, False) * 1e3
    return out
