"""Conversion at the kernel's boundary: machine, effects, commands and faults to SI arrays."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from monitor.sim import kernel as K
from monitor.sim.corrections import pack_corrections
from monitor.sim.effects import Effect
from monitor.sim.faults import Fault, fault_inputs
from monitor.sim.laws import P_ATM
from monitor.sim.machine import BAR, LPM, MachineParams

#: Smoothing velocity of the friction sign (m/s) unless the effect sets one: well below any
#: speed of interest.
FRICTION_SMOOTHING_M_S = 5e-4


def walther_constants(nu40_cst: float, nu100_cst: float) -> tuple[float, float]:
    """A, B of log10(log10(nu + 0.7)) = A - B log10(T_K) through two reference points."""
    t1, t2 = math.log10(313.15), math.log10(373.15)
    w1 = math.log10(math.log10(nu40_cst + 0.7))
    w2 = math.log10(math.log10(nu100_cst + 0.7))
    b = (w1 - w2) / (t2 - t1)
    return w1 + b * t1, b


def viscosity_cst(temp_c: np.ndarray, nu40_cst: float, nu100_cst: float) -> np.ndarray:
    """Kinematic viscosity (cSt) at ``temp_c`` from the Walther equation (ASTM D341)."""
    a, b = walther_constants(nu40_cst, nu100_cst)
    tk = np.maximum(np.asarray(temp_c, dtype=np.float64), -40.0) + 273.15
    return 10.0 ** (10.0 ** (a - b * np.log10(tk))) - 0.7


def pack_params(
    machine: MachineParams,
    effects: list[Effect] | tuple[Effect, ...] = (),
    corrections: Mapping[str, float] | None = None,
) -> np.ndarray:
    """The kernel's parameter vector for a machine with the given effects switched on and
    the given data-driven ``corrections`` (``monitor.sim.corrections``, SI) added."""
    m = machine
    prm = np.zeros(K.N_PARAMS)
    prm[K.BETA] = m.oil.bulk_modulus_pa
    prm[K.V_LINE] = m.line.line_volume_m3
    prm[K.V0A] = m.cylinder.dead_volume_a_m3
    prm[K.V0B] = m.cylinder.dead_volume_b_m3
    prm[K.AA] = m.cylinder.area_a_m2
    prm[K.AB] = m.cylinder.area_b_m2
    prm[K.STROKE] = m.cylinder.stroke_m
    prm[K.MASS] = m.load.mass_kg
    prm[K.FGRAV] = m.load.gravity_load_n
    prm[K.CVISC] = m.load.viscous_friction_n_s_m
    prm[K.KV] = m.valve.valve_kv
    prm[K.DP_LAM] = m.valve.laminar_dp_pa
    prm[K.PTANK] = m.valve.tank_pa
    prm[K.NOTCH] = m.valve.notch_share
    prm[K.FLOW_FORCE] = m.valve.flow_force
    if m.valve.flow_force > 0.0:
        # The rated flow is the flow at the rated drop across each edge with the flow forces
        # that drop sets: the open edge's own coefficient is that much larger.
        prm[K.KV] *= 1.0 + m.valve.flow_force * 2.0 * m.valve.valve_rated_dp_pa
    prm[K.DISP_MAX] = m.pump.pump_disp_m3_rev
    prm[K.COMP_ON] = 1.0 if m.pump.compensator_enabled else 0.0
    prm[K.COMP_START] = m.pump.compensator_start_pa
    prm[K.COMP_FULL] = m.pump.compensator_full_pa
    prm[K.RELIEF_CRACK] = m.line.relief_crack_pa
    prm[K.RELIEF_GAIN] = m.relief_gain_m3_s_pa
    prm[K.XREF] = m.load.reference_rod_pos_m
    prm[K.V_EPS] = FRICTION_SMOOTHING_M_S
    prm[K.WN] = 1.0  # harmless values for switched-off effects
    prm[K.TAU_PUMP] = 1.0
    prm[K.E_WALL] = 1e9
    prm[K.AIR_N] = 1.4
    prm[K.VS] = 0.01
    prm[K.STRIBECK_EXP] = 2.0
    prm[K.AIR_PCRIT] = 1e7
    for effect in effects:
        _pack_effect(prm, effect)
    if corrections:
        pack_corrections(prm, corrections)
    return prm


def _pack_effect(prm: np.ndarray, effect: Effect) -> None:
    p = effect.params
    name = effect.name
    if name == "entrained_air":
        prm[K.AIR_ON] = 1.0
        prm[K.AIR_ALPHA] = p["air_fraction"]
        prm[K.AIR_N] = p["polytropic_index"]
        if effect.labels.get("law", "free_air") == "dissolving":
            prm[K.AIR_LAW] = 1.0
            prm[K.AIR_PCRIT] = p["dissolved_at_bar"] * BAR + P_ATM
    elif name == "oil_viscosity":
        prm[K.VISC_ON] = 1.0
        prm[K.LEAK_K] = p["pump_leak_lpm_per_100bar"] * LPM / (100 * BAR)
        prm[K.FRIC_SHARE] = p["friction_share"]
        prm[K.PISTON_LEAK] = p["piston_leak_lpm_per_100bar"] * LPM / (100 * BAR)
        prm[K.VALVE_LEAK] = p["valve_leak_lpm_per_100bar"] * LPM / (100 * BAR)
    elif name == "cylinder_friction":
        prm[K.FRIC_ON] = 1.0
        prm[K.FC] = p["coulomb_n"]
        prm[K.FS] = p["static_n"]
        prm[K.VS] = p["stribeck_velocity_mm_s"] * 1e-3
        prm[K.STRIBECK_EXP] = p["stribeck_exponent"]
        prm[K.V_EPS] = p["smoothing_velocity_mm_s"] * 1e-3
    elif name == "spool_dynamics":
        prm[K.SPOOL_ON] = 1.0
        prm[K.WN] = 2 * math.pi * p["natural_freq_hz"]
        prm[K.ZETA] = p["damping_ratio"]
    elif name == "valve_deadband":
        prm[K.OVERLAP] = p["overlap_pct"] / 100.0
    elif name == "pump_control_dynamics":
        prm[K.PUMPDYN_ON] = 1.0
        prm[K.TAU_PUMP] = p["time_constant_ms"] * 1e-3
        if effect.labels.get("law", "first_order") == "second_order":
            prm[K.PUMP_WN] = 2 * math.pi * p["natural_freq_hz"]
            prm[K.PUMP_ZETA] = p["damping_ratio"]
    elif name == "hose_compliance":
        prm[K.HOSE_ON] = 1.0
        if effect.labels.get("law", "series_modulus") == "added_capacitance":
            prm[K.E_WALL] = math.inf  # no wall term: the lines' own capacitances instead
            prm[K.HOSE_C_LINE] = p["line_capacitance_cm3_per_bar"] * 1e-6 / BAR
            prm[K.HOSE_C_CYL] = p["cylinder_capacitance_cm3_per_bar"] * 1e-6 / BAR
        else:
            prm[K.E_WALL] = p["wall_modulus_gpa"] * 1e9
    elif name == "load_variation":
        prm[K.SLOPE] = p["slope_n_per_mm"] * 1e3
        prm[K.CURV] = p["curvature_n_per_mm2"] * 1e6
    elif name not in ("sensor_lag", "sensor_calibration"):  # these act on the sensor model
        raise ValueError(f"effect {name!r} has no kernel packing")


def pack_inputs(
    t_s: np.ndarray,
    spool_pct: np.ndarray,
    disp_pct: np.ndarray,
    speed_rpm: np.ndarray,
    oil_temp_c: np.ndarray,
    faults: list[Fault] | tuple[Fault, ...] = (),
    effects: list[Effect] | tuple[Effect, ...] = (),
) -> np.ndarray:
    """Kernel input rows (SI fractions and rev/s) on the command time axis.

    The viscosity ratio nu(OilTemp)/nu40 depends only on the input, so it is computed here
    once per sample rather than in every right-hand-side call.
    """
    n = len(t_s)
    u = np.empty((n, K.N_INPUTS))
    u[:, K.IN_SPOOL] = np.clip(spool_pct, -100.0, 100.0) / 100.0
    u[:, K.IN_DISP] = np.clip(disp_pct, 0.0, 100.0) / 100.0
    u[:, K.IN_SPEED_RPS] = np.maximum(speed_rpm, 0.0) / 60.0
    u[:, K.IN_VISC_RATIO] = 1.0
    for effect in effects:
        if effect.name == "oil_viscosity":
            nu40, nu100 = effect.params["nu40_cst"], effect.params["nu100_cst"]
            u[:, K.IN_VISC_RATIO] = viscosity_cst(oil_temp_c, nu40, nu100) / nu40
    f = fault_inputs(list(faults), t_s)
    u[:, K.IN_LEAK] = f["piston_leak_m3_s_pa"]
    u[:, K.IN_STROKE_LIM] = f["stroke_limit"]
    u[:, K.IN_UNDERLAP] = f["underlap"]
    u[:, K.IN_TIME] = t_s
    return u


def rest_state(
    machine: MachineParams, prm: np.ndarray, rod_pos_m: float, spool: float = 0.0, disp: float = 1.0
) -> np.ndarray:
    """A state at rest: rod held at ``rod_pos_m``, pump line at its dead-head pressure."""
    m = machine
    y = np.zeros(K.N_STATES)
    x = min(max(rod_pos_m, 0.0), m.cylinder.stroke_m)
    pb = 2 * BAR  # a little trapped rod-side pressure
    dx = x - m.load.reference_rod_pos_m
    f_grav = m.load.gravity_load_n + prm[K.SLOPE] * dx + prm[K.CURV] * dx * dx
    y[K.S_PP] = m.pump.compensator_full_pa if m.pump.compensator_enabled else m.line.relief_crack_pa
    y[K.S_PB] = pb
    y[K.S_PA] = max((f_grav + pb * m.cylinder.area_b_m2) / m.cylinder.area_a_m2, 0.0)
    y[K.S_X] = x
    y[K.S_XS] = spool
    y[K.S_DISP] = 0.0 if m.pump.compensator_enabled else disp
    return y


def measured_state(
    machine: MachineParams,
    prm: np.ndarray,
    pp_pa: float,
    pa_pa: float,
    pb_pa: float,
    rod_pos_m: float,
    rod_vel_m_s: float = 0.0,
    spool: float = 0.0,
    disp: float | None = None,
) -> np.ndarray:
    """A state taken from measurements, to start a simulation mid-recording.

    The spool (fraction of stroke) starts at rest at ``spool``.  ``disp`` (fraction) defaults
    to what the compensator allows at ``pp_pa`` with full command: without pump dynamics the
    kernel ignores it, with them it is the best guess a pressure reading gives.
    """
    m = machine
    y = np.zeros(K.N_STATES)
    y[K.S_PP] = max(pp_pa, 0.0)
    y[K.S_PA] = max(pa_pa, 0.0)
    y[K.S_PB] = max(pb_pa, 0.0)
    y[K.S_X] = min(max(rod_pos_m, 0.0), m.cylinder.stroke_m)
    y[K.S_V] = rod_vel_m_s
    y[K.S_XS] = spool
    if disp is None:
        disp = 1.0
        if m.pump.compensator_enabled:
            span = m.pump.compensator_full_pa - m.pump.compensator_start_pa
            disp = min(max((m.pump.compensator_full_pa - pp_pa) / span, 0.0), 1.0)
    y[K.S_DISP] = disp
    return y
