"""The hydraulic loop's laws as scalar functions: orifices, the oil's capacitance with
entrained and dissolving air, the pump's displacement and flow, and the data-driven
corrections.  SI throughout (Pa, m^3/s, m, N, s).

They take scalars and tuples, never the parameter or state arrays (``monitor.sim.kernel``
reads those and passes the values down): numba's inliner wraps every array argument in an
atomic reference count increment and decrement, which took half of a step's time.  Shared
by the boom loop's kernel and the whole machine's.
"""

from __future__ import annotations

import math

from monitor.jit import jit

P_ATM = 101325.0
LOG_P_ATM = math.log(P_ATM)


@jit(inline="always")
def orifice(kv_open: float, dp: float, dp_lam: float) -> float:
    """Turbulent orifice flow kv*sqrt(dp), turning smoothly laminar below ~dp_lam."""
    if kv_open == 0.0:  # a closed edge (half of them at any time): skip two roots
        return 0.0
    return kv_open * dp / math.sqrt(math.sqrt(dp * dp + dp_lam * dp_lam))


@jit(inline="always")
def metering(opening: float, notch: float) -> float:
    """The open area of a metering edge (share of its full-stroke area) at ``opening``
    (share of the stroke past the lap) when notches meter the first ``notch`` of the stroke:
    a V notch's area grows with the square of its opening, then the full land opens
    linearly; the two joined with one slope, ``notch / (2 - notch)`` of the area at the
    notch's end (a third at half the stroke).  ``notch`` 0 < n < 1."""
    at_end = notch / (2.0 - notch)
    if opening < notch:
        r = opening / notch
        return at_end * r * r
    return at_end + (opening - notch) * (1.0 - at_end) / (1.0 - notch)


@jit(inline="always")
def flow_forced(xs: float, pp: float, pa: float, pb: float, ptank: float, k: float) -> float:
    """The spool's position ``xs`` (share of the stroke) where steady flow forces close it
    against its centring spring: each open metering edge pulls the spool shut with a force
    proportional to its opening times its pressure drop, so a spool the solenoid (or pilot)
    sends to ``xs`` settles at ``xs / (1 + k * (drop in + drop out))`` (``k`` in 1/Pa: the
    flow forces' gain over the spring's rate).  The drops of the edges ``xs`` opens: P->A
    and B->T raising, P->B and A->T lowering; a negative drop pushes nothing."""
    if xs >= 0.0:
        drops = max(pp - pa, 0.0) + max(pb - ptank, 0.0)
    else:
        drops = max(pp - pb, 0.0) + max(pa - ptank, 0.0)
    return xs / (1.0 + k * drops)


@jit(inline="always")
def clip(v: float, lo: float, hi: float) -> float:
    return lo if v < lo else (hi if v > hi else v)


@jit
def capacitance(p: float, vol: float, hose_vol: float, hose_c: float, oil: tuple) -> float:
    """``_compliance`` with the parameters as ``_oil`` reads them."""
    beta, air_on, air_n, air_alpha, air_law, air_pcrit, hose_on, e_wall = oil
    if air_on > 0.0:
        # Simscape's entrained-air modulus; p absolute, never below 1 kPa.  The air's
        # softness is kept as 1/modulus (fewer divisions one after the other: air doubled
        # the cost of a step) and its compression as exp(log): log(pabs) needs no division
        # first.
        pabs = max(p + P_ATM, 1e3)
        n = air_n
        r = math.exp((LOG_P_ATM - math.log(pabs)) / n)
        a = air_alpha
        if air_law > 0.0:
            c = vol * dissolving_air(beta, pabs, a, r, n, air_pcrit)
        else:
            ar = a * r
            c = vol * (1.0 + ar * beta / (n * pabs)) / (beta * (1.0 + ar))
    else:
        c = vol / beta
    if hose_on > 0.0:
        c += hose_vol / e_wall + hose_c
    return c


@jit
def dissolving_air(beta: float, pabs: float, a: float, r: float, n: float, pcrit: float) -> float:
    """Softness 1/modulus (1/Pa) when the free air (fraction a at atmosphere, compressed
    polytropically: r = (p0/p)^(1/n)) also dissolves, linearly in pressure from atmospheric
    (all free) to ``pcrit`` (none free).  Gas volume a*theta*r per liquid volume, so
    d(gas)/dp = a*(theta*r/(n p) + r/(pcrit - p0)) below pcrit; pure liquid above it."""
    if pabs >= pcrit:
        return 1.0 / beta
    span = pcrit - P_ATM
    theta = clip((pcrit - pabs) / span, 0.0, 1.0)
    soft = a * (theta * r / (n * pabs) + r / span)
    return (1.0 / beta + soft) / (1.0 + a * theta * r)


@jit
def disp_target(pp: float, disp_cmd: float, comp: tuple) -> float:
    """Displacement fraction the pump is commanded to: command times compensator destroke
    (``comp``: ``_compensator``)."""
    comp_on, comp_start, comp_full = comp
    destroke = 1.0
    if comp_on > 0.0:
        destroke = clip((comp_full - pp) / (comp_full - comp_start), 0.0, 1.0)
    return disp_cmd * destroke


@jit
def pump_flow(
    pp: float, disp_state: float, speed_rps: float, visc_ratio: float, target: float, pump: tuple
) -> float:
    """Pump outlet flow QP (m^3/s) at displacement ``target`` (the lagged state
    ``disp_state`` instead with pump dynamics), less the viscosity-dependent internal
    leakage (``pump``: ``_pump``)."""
    pumpdyn_on, disp_max, visc_on, leak_k = pump
    pp = max(pp, 0.0)
    # A ringing swashplate overshoots its target but not its stops.
    disp = clip(disp_state, 0.0, 1.0) if pumpdyn_on > 0.0 else target
    qp = disp * disp_max * speed_rps
    if visc_on > 0.0:
        qp -= leak_k * pp / visc_ratio  # nu(OilTemp) / nu40, precomputed per sample
    return qp


@jit
def leak(k_lin: float, k_sqrt: float, dp: float, dp_lam: float) -> float:
    """A correction leakage (m^3/s): laminar k_lin*dp plus orifice-like k_sqrt*sqrt(dp)."""
    q = 0.0
    if k_lin != 0.0:
        q += k_lin * dp
    if k_sqrt != 0.0:
        q += orifice(k_sqrt, dp, dp_lam)
    return q


@jit
def edge_corrections(q_pa: float, q_bt: float, q_pb: float, q_at: float, rel: tuple):
    """Metering edge flows scaled by (1 + relative gain change) per edge (``rel``: the
    changes of P->A, B->T, P->B, A->T)."""
    pa_rel, bt_rel, pb_rel, at_rel = rel
    if pa_rel != 0.0:
        q_pa *= 1.0 + pa_rel
    if bt_rel != 0.0:
        q_bt *= 1.0 + bt_rel
    if pb_rel != 0.0:
        q_pb *= 1.0 + pb_rel
    if at_rel != 0.0:
        q_at *= 1.0 + at_rel
    return q_pa, q_bt, q_pb, q_at


@jit
def force_corrections(
    f_load: float, f_fric: float, x: float, v: float, t: float, terms: tuple
) -> tuple[float, float]:
    """Correction forces on the rod (N): position and periodic terms act as load, velocity
    and sign(velocity) terms as friction (``terms``: ``_force_terms``)."""
    f_pos, xref, f_cos, f_sin, f_w, f_vel, f_sign, v_eps = terms
    if f_pos != 0.0:
        f_load += f_pos * (x - xref)
    if f_cos != 0.0 or f_sin != 0.0:
        w = f_w * t
        f_load += f_cos * math.cos(w) + f_sin * math.sin(w)
    if f_vel != 0.0:
        f_fric += f_vel * v
    if f_sign != 0.0:
        f_fric += f_sign * math.tanh(v / v_eps)
    return f_load, f_fric
