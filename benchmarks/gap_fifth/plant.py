"""Run the fifth plant: commands in, true traces out (one row a millisecond)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from benchmarks.gap_fifth import kernel as kn
from benchmarks.gap_fifth import params as pr

SUBSTEPS = 4  # RK4 steps a millisecond (250 us)


@dataclass(frozen=True)
class Commands:
    """One value a millisecond: spool (-1..1), displacement limit (0..1), engine set point
    (rpm), oil temperature (degC), other engine loads (N m)."""

    spool: np.ndarray
    disp: np.ndarray
    rpm_set: np.ndarray
    temp_c: np.ndarray
    torque_nm: np.ndarray


def psi_at(values: dict[str, float], stroke_m: float) -> float:
    """The pivot's included angle at a stroke (law of cosines)."""
    a, b = values["link_a_m"], values["link_b_m"]
    length = values["cyl_l0_m"] + stroke_m
    return math.acos((a * a + b * b - length * length) / (2 * a * b))


def initial_state(
    values: dict[str, float], stroke_m: float, rpm: float, disp: float = 1.0
) -> np.ndarray:
    """At rest, spool centred, the rod held where it is by chamber A (B at tank pressure);
    the pump at its stand-by (load sensing) or at its setting, nearly destroked (compensated:
    the control piston's pressure balancing the bias spring; the stop at `disp`, 0..1)."""
    y = np.zeros(kn.N_STATES)
    psi = psi_at(values, stroke_m)
    a, b = values["link_a_m"], values["link_b_m"]
    arm = a * b * math.sin(psi) / (values["cyl_l0_m"] + stroke_m)
    theta = psi - values["psi_off_rad"]
    grav = values["boom_mgl"] * math.cos(theta)
    if values["bal_f0_n"]:
        squeeze = values["stroke_m"] - stroke_m
        g = values["bal_gas_m"]
        grav -= arm * values["bal_f0_n"] * (g / (g - squeeze)) ** 1.3
    pt = values["tank_p0_pa"]
    y[kn.S_PSI] = psi
    y[kn.S_PB] = pt
    y[kn.S_PA] = (grav / arm + pt * values["area_b"]) / values["area_a"]
    y[kn.S_PT] = pt
    y[kn.S_PP] = values["margin_pa"] + pt
    y[kn.S_PLS] = pt
    y[kn.S_WE] = rpm * math.pi / 30.0
    y[kn.S_GI] = 8.0
    y[kn.S_ALPHA] = 0.05
    if values["pump_pc"]:
        pp = values["comp_set_pa"] + 0.95 * values["comp_droop_pa"]
        x = (1.0 - 0.05) * values["ctl_stroke_m"]
        bias = values["bias_f0_n"] + values["bias_k_n_m"] * x - values["swash_moment_m2"] * pp
        y[kn.S_PP] = y[kn.S_PLS] = pp
        y[kn.S_PC] = bias / values["ctl_piston_m2"]
        y[kn.S_LIM] = disp
    return y


def run(values: dict[str, float], cmd: Commands, nu_cst: np.ndarray, stroke0_m: float = 0.2):
    """True traces (kernel.OUT_NAMES as a dict of arrays, SI), one a millisecond."""
    n = cmd.spool.size
    inputs = np.empty((n, 6))
    inputs[:, 0] = cmd.spool
    inputs[:, 1] = cmd.disp
    inputs[:, 2] = cmd.rpm_set * math.pi / 30.0
    inputs[:, 3] = nu_cst
    inputs[:, 4] = cmd.torque_nm
    inputs[:, 5] = np.arange(n) * 1e-3
    p = pr.vector(values)
    y0 = initial_state(values, stroke0_m, float(cmd.rpm_set[0]), float(cmd.disp[0]))
    out, _ = kn.integrate(p, y0, inputs, SUBSTEPS)
    return {name: out[:, k] for k, name in enumerate(kn.OUT_NAMES)}
