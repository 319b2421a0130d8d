"""Run the whole machine: duty-cycle commands in, every loop's dbc/excavator4.dbc signals out.

What each loop's sensors read: PP is the one pump line's pressure at each section's inlet
(the same gallery, each sensor with its own noise), PA and PB the section's ports, QP the
section's supply flow (P->A plus P->B after its compensator: what that function draws from
the shared pump), RodPos the cylinder's stroke (boom, stick, bucket; the swing has none).
Noise, ranges and the bus's resolution are the boom loop's (monitor/sim/sensors.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monitor.io.recording import Recording
from monitor.sim.machine import BAR
from monitor.sim.sensors import SensorParams, measure, quantise, sample_hold
from monitor.sim.whole import kernel as K
from monitor.sim.whole.cycles import SPOOL_SIGNALS
from monitor.sim.whole.faults import MachineFault, fill_fault_inputs
from monitor.sim.whole.params import CYLINDERS, WholeMachine, pack_params

M3S_PER_LPM = 1e-3 / 60.0
#: Each loop's DBC prefix (the boom's frames are the reference loop's, unprefixed).
PREFIX = {"boom": "", "stick": "Stick_", "bucket": "Bucket_", "swing": "Swing_"}
#: Rod positions at the start, fraction of stroke (the cycles' first estimate).
START_FRACTION = 0.3


@dataclass
class WholeTrace:
    """True plant values (SI) at the commands' sample times: ``rec`` columns as
    ``kernel.R_*`` (PP, pump flow, then per loop PA, PB, section flow, X, V)."""

    t_s: np.ndarray
    rec: np.ndarray

    def loop(self, name: str, what: int) -> np.ndarray:
        """``what``: 0 PA, 1 PB, 2 section flow, 3 position, 4 velocity."""
        return self.rec[:, K.R0 + K.NR * K.LOOPS.index(name) + what]


def pack_inputs(commands: Recording, faults: list[MachineFault] | tuple = ()) -> np.ndarray:
    """Kernel input rows on the commands' time axis."""
    t = commands.t
    u = np.zeros((len(t), K.N_INPUTS))
    u[:, K.IN_SPEED_RPS] = np.maximum(commands["EngineSpeed"], 0.0) / 60.0
    u[:, K.IN_DIG_N] = commands["DigForce"] if commands.has("DigForce") else 0.0
    u[:, K.IN_PAYLOAD_KG] = commands["Payload"] if commands.has("Payload") else 0.0
    for j, loop in enumerate(K.LOOPS):
        u[:, K.IN0 + K.NI * j + K.I_SPOOL] = np.clip(commands[SPOOL_SIGNALS[loop]], -100, 100) / 100
    fill_fault_inputs(list(faults), t, u)
    return u


def rest_state(
    machine: WholeMachine,
    prm: np.ndarray,
    u0: np.ndarray,
    fractions: dict[str, float] | None = None,
) -> np.ndarray:
    """At rest: PP at standby (the LS margin), the LS line drained, every cylinder holding
    its gravity load at ``fractions`` of its stroke with 2 bar on the side that does not
    hold it."""
    y = np.zeros(K.N_STATES)
    y[K.S_PP] = prm[K.LS_MARGIN]
    y[K.S_LS] = prm[K.PTANK]
    for j, loop in enumerate(CYLINDERS):
        frac = (fractions or {}).get(loop, START_FRACTION)
        y[K.S0 + K.NS * j + K.X_X] = frac * machine.stroke_m(loop)
    forces = K.pose_forces(y, u0, prm)
    low = 2 * BAR
    for j, loop in enumerate(CYLINDERS):
        b = K.S0 + K.NS * j
        aa, ab = machine.area_a_m2(loop), machine.area_b_m2(loop)
        if forces[j] >= 0:
            y[b + K.X_PB] = low
            y[b + K.X_PA] = (forces[j] + low * ab) / aa
        else:
            y[b + K.X_PA] = low
            y[b + K.X_PB] = (-forces[j] + low * aa) / ab
    return y


def run_whole(
    commands: Recording,
    machine: WholeMachine,
    faults: list[MachineFault] | tuple = (),
    y0: np.ndarray | None = None,
    prm: np.ndarray | None = None,
) -> WholeTrace:
    """Integrate the whole machine driven by ``commands`` (a uniform axis), recorded at
    the commands' samples."""
    prm = pack_params(machine) if prm is None else prm
    u = pack_inputs(commands, faults)
    input_dt = float(commands.t[1] - commands.t[0])
    if y0 is None:
        y0 = rest_state(machine, prm, u[0])
    n_sub = max(1, int(round(input_dt / machine.step_s)))
    rec = K.integrate(y0, u, n_sub, input_dt, prm, n_sub)
    return WholeTrace(commands.t.copy(), rec)


def sense(
    commands: Recording, trace: WholeTrace, seed: int | None, sensors: SensorParams | None = None
) -> Recording:
    """Every loop's DBC signals; ``seed=None``: noise-free (still quantised)."""
    s = sensors or SensorParams()
    rng = np.random.default_rng(seed) if seed is not None else None
    t = commands.t
    out: dict[str, np.ndarray] = {}
    out["EngineSpeed"] = quantise("EngineSpeed", commands["EngineSpeed"])
    out["OilTemp"] = quantise(
        "OilTemp", sample_hold(t - t[0], commands["OilTemp"], s.oil_temp_period_s)
    )
    pp = trace.rec[:, K.R_PP] / BAR
    for loop in K.LOOPS:
        pre = PREFIX[loop]
        out[pre + "SpoolCmd"] = quantise("SpoolCmd", commands[SPOOL_SIGNALS[loop]])
        # A load-sensing pump takes no displacement command: the lever is the demand.
        out[pre + "PumpDispCmd"] = np.full_like(t, 100.0)
        out[pre + "PP"] = measure("PP", pp, s.pressure_noise_bar, s.pressure_range_bar, rng)
        for name, what in (("PA", 0), ("PB", 1)):
            out[pre + name] = measure(
                name, trace.loop(loop, what) / BAR, s.pressure_noise_bar, s.pressure_range_bar, rng
            )
        out[pre + "QP"] = measure(
            "QP", trace.loop(loop, 2) / M3S_PER_LPM, s.flow_noise_lpm, s.flow_range_lpm, rng
        )
        if loop != "swing":
            out[pre + "RodPos"] = measure(
                "RodPos", trace.loop(loop, 3) * 1e3, s.rodpos_noise_mm, s.rodpos_range_mm, rng
            )
    return Recording(
        t.copy(),
        out,
        source=f"whole-machine simulation of {commands.source}",
        meta={"machine": "excavator4", "seed": seed},
    )


def simulate_whole(
    commands: Recording,
    machine: WholeMachine,
    faults: list[MachineFault] | tuple = (),
    seed: int | None = 0,
) -> Recording:
    """Commands (``cycles.make_whole_cycle``) to every loop's DBC signals at 100 Hz."""
    return sense(commands, run_whole(commands, machine, faults), seed)
