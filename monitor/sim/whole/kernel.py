"""The whole machine's numba kernel: one load-sensing pump, four post-compensated sections
(boom, stick, bucket cylinders and the swing motor), a planar boom-stick-bucket chain.

SI inside (Pa, m^3/s, m, rad, kg, N, s).  Parameters travel as one float64 vector and the
per-sample inputs as rows (indices below; ``params.py`` and ``simulate.py`` fill them).
The orifice rule is the reference loop's (``monitor.sim.laws.orifice``); the rest of a
section (spool openings with the stroke limit and the worn edges' underlap, piston leakage,
end stops, chamber compressibility) follows the boom loop's formulation in
``monitor.sim.kernel.rhs`` with a compensated meter-in edge.

Flow sharing (why post-compensated): each section's pressure compensator sits after its
spool's meter-in edge and is piloted by the highest load pressure PLS, so every open spool
sees the same drop PP - PLS.  A section's flow is Kv * opening * sqrt(PP - PLS): while the
pump keeps up, the drop is the LS margin and each section gets its own demand whatever its
load; when the demand exceeds the pump's flow, PP falls, the common drop shrinks, and every
section's flow is scaled by the same factor, sqrt(drop / margin) = pump flow / total demand.
Nothing stalls: the heaviest function slows in proportion instead of stopping, which is why
load-sensing mini excavators (and this simulator) use post-compensation ("flow sharing",
LUDV).  A pre-compensated valve would starve the highest load under saturation; negative
flow control on an open-centre valve (``NEGATIVE_FLOW_CONTROL``) is named for later.

The LS line: while a spool is open the shuttle chain holds it at the highest open section's
feeding port (the passage is far larger than the bleed, taken as ideal); the line's state
follows that port with the passage's time constant ``LS_TRACK_S``.  With every spool closed
the spools cut it from the ports and it drains to tank through the bleed orifice (laminar):
dPLS/dt = -(beta / V_ls) G_bleed (PLS - p_tank), a time constant V_ls / (beta G_bleed).

The pump is a proportional LS regulator: displacement = (PLS + margin - PP) / band, limited
to 0..1 and cut off between cutoff_start and cutoff_full, less its internal leakage to the
case (healthy, and more of it when worn: ``pump_wear``).  That leakage is what brings PP
down once the LS signal has drained and the pump has destroked: PP falls with the time
constant V_line / (beta G_pump) until the regulator holds it at the standby pressure
(the margin above the drained LS line, less the leakage's share of the band).
Anti-cavitation: ideal make-up checks from tank (no port falls below tank pressure; the
projection after each step is that check).  Main relief on the pump line, crossover reliefs
A<->B on the swing motor.
"""

from __future__ import annotations

import math

import numpy as np

from monitor.jit import jit
from monitor.sim import rk4
from monitor.sim.laws import clip, orifice

#: Named for later: an open-centre valve with negative flow control (issue 39).
NEGATIVE_FLOW_CONTROL = "negative_flow_control"
LOOPS = ("boom", "stick", "bucket", "swing")
N_LOOPS = 4
SWING = 3

# --- parameter vector ----------------------------------------------------------------------
BETA, V_LINE, DISP_MAX, LS_MARGIN, LS_BAND, CUT_START, CUT_FULL = 0, 1, 2, 3, 4, 5, 6
RELIEF_CRACK, RELIEF_GAIN, DP_LAM, PTANK, GRAV = 7, 8, 9, 10, 11
XR_CRACK, XR_GAIN, MOTOR_LEAK, V_EPS_DIG = 12, 13, 14, 15
# the chain: link lengths, masses, moment arms, angle offsets (boom absolute, others relative)
L1, L2, L3, M1, M2, M3, R1, R2, R3, A1, A2, A3 = range(16, 28)
# the LS line: volume, bleed conductance (m^3/s/Pa); the pump's healthy leakage (m^3/s/Pa)
V_LS, LS_BLEED, PUMP_LEAK = 28, 29, 30
LOOP0, NL = 31, 8  # per loop block: LOOP0 + NL * loop + one of:
P_KV, P_AA, P_AB, P_STROKE, P_V0A, P_V0B, P_MASS, P_CVISC = range(8)
N_PARAMS = LOOP0 + NL * N_LOOPS

# --- input columns -------------------------------------------------------------------------
IN_SPEED_RPS, IN_DIG_N, IN_PAYLOAD_KG, IN_PUMP_LEAK = 0, 1, 2, 3
IN0, NI = 4, 4  # per loop block: IN0 + NI * loop + one of:
I_SPOOL, I_STROKE_LIM, I_UNDERLAP, I_LEAK = range(4)
N_INPUTS = IN0 + NI * N_LOOPS

# --- states: PP, then per loop PA, PB, X (rod m / house rad), V (m/s / rad/s), then PLS ----
S_PP = 0
S0, NS = 1, 4
X_PA, X_PB, X_X, X_V = range(4)
S_LS = S0 + NS * N_LOOPS
N_STATES = S_LS + 1
#: Time constant (s) of the LS line following the highest open port through the shuttles:
#: short against the 10 ms samples, long against the 200 us RK4 step (stable).
LS_TRACK_S = 0.002

# --- recorded (100 Hz): PP, pump flow, per loop PA, PB, section flow, X, V; PLS ------------
R_PP, R_QP = 0, 1
R0, NR = 2, 5
R_LS = R0 + NR * N_LOOPS  # and the LS line's pressure last
N_RECORD = R_LS + 1

# --- auxiliary outputs of the right-hand side ---------------------------------------------
AUX_QP, AUX_PLS = 0, 1
AUX_Q0 = 2  # + loop: the section's supply flow (P->A plus P->B)
N_AUX = AUX_Q0 + N_LOOPS


# The helpers below take scalars and tuples of parameters, never the state, input or
# parameter arrays: numba's inliner wraps every array argument in an atomic reference count
# increment and decrement (the boom loop's kernel, monitor/sim/kernel.py, says more).


@jit(inline="always")
def _chain(prm: np.ndarray) -> tuple:
    """The chain's parameters as ``chain_forces`` takes them."""
    return (
        prm[A1], prm[A2], prm[A3], prm[R1], prm[R2], prm[R3], prm[L1], prm[L2], prm[L3],
        prm[M1], prm[M2], prm[M3], prm[GRAV], prm[V_EPS_DIG],
    )  # fmt: skip


@jit
def chain_forces(
    x1: float, x2: float, x3: float, v2: float, v3: float, payload: float, dig: float, ch: tuple
) -> tuple[float, float, float]:
    """Gravity and digging forces on the boom, stick and bucket cylinders (N, positive
    against extension) from the rods' positions ``x1..x3`` (m) and the stick's and bucket's
    speeds (m/s): potential energy V(x), force dV/dx = (dtheta/dx) dV/dtheta with a
    constant moment arm per cylinder (dtheta/dx = +-1/R).  ``ch``: ``_chain``."""
    pa1, pa2, pa3, r1, r2, r3, l1, l2, l3, m1, m2, m3, g, ve = ch
    a1 = pa1 + x1 / r1
    a2 = a1 + pa2 - x2 / r2  # extending the stick curls it in
    a3 = a2 + pa3 - x3 / r3  # extending the bucket curls it
    c1, c2, c3 = math.cos(a1), math.cos(a2), math.cos(a3)
    p1x = l1 * c1
    p1y = l1 * math.sin(a1)
    p2x = p1x + l2 * c2
    p2y = p1y + l2 * math.sin(a2)
    g1 = 0.5 * l1 * c1
    g2 = p1x + 0.5 * l2 * c2
    g3 = p2x + 0.5 * l3 * c3
    m3 = m3 + payload
    t1 = g * (m1 * g1 + m2 * g2 + m3 * g3)
    t2 = g * (m2 * (g2 - p1x) + m3 * (g3 - p1x))
    t3 = g * m3 * (g3 - p2x)
    f0 = t1 / r1
    f1 = -t2 / r2
    f2 = -t3 / r3
    # Digging: a tip force against the curl, resisting stick and bucket while they move
    # (like friction: soil does not push a standing bucket back).
    if dig != 0.0:
        tipx = p2x + l3 * c3
        tipy = p2y + l3 * math.sin(a3)
        rr = math.sqrt((tipx - p1x) ** 2 + (tipy - p1y) ** 2)
        f1 += dig * rr / r2 * math.tanh(v2 / ve)
        f2 += dig * l3 / r3 * math.tanh(v3 / ve)
    return f0, f1, f2


@jit
def pose_forces(y: np.ndarray, u: np.ndarray, prm: np.ndarray) -> tuple[float, float, float]:
    """``chain_forces`` at state ``y`` and input row ``u`` (for the rest state, not the step)."""
    return chain_forces(
        y[S0 + X_X], y[S0 + NS + X_X], y[S0 + 2 * NS + X_X], y[S0 + NS + X_V],
        y[S0 + 2 * NS + X_V], u[IN_PAYLOAD_KG], u[IN_DIG_N], _chain(prm),
    )  # fmt: skip


@jit(inline="always")
def _opening(spool: float, lim: float, ul: float) -> tuple[float, float, float]:
    """Signed spool s and the P->A/B->T and P->B/A->T openings (boom loop's rule)."""
    s = clip(spool, -lim, lim)
    return s, clip(s + ul, 0.0, 1.0), clip(-s + ul, 0.0, 1.0)


@jit(inline="always")
def _loop_inputs(u: np.ndarray, k: int) -> tuple[float, float, float, float]:
    """Input ``k`` (``I_SPOOL`` ...) of the four loops."""
    return u[IN0 + k], u[IN0 + NI + k], u[IN0 + 2 * NI + k], u[IN0 + 3 * NI + k]


@jit
def rhs(y: np.ndarray, u: np.ndarray, prm: np.ndarray, dy: np.ndarray, aux: np.ndarray) -> None:
    """Write dy/dt into ``dy`` and the pump flow, PLS and section flows into ``aux``."""
    # The inputs read at once, before any branch (see the helpers' note above).
    spools, lims = _loop_inputs(u, I_SPOOL), _loop_inputs(u, I_STROKE_LIM)
    underlaps, leaks = _loop_inputs(u, I_UNDERLAP), _loop_inputs(u, I_LEAK)
    speed_rps, dig = u[IN_SPEED_RPS], u[IN_DIG_N]
    payload, pump_leak = u[IN_PAYLOAD_KG], u[IN_PUMP_LEAK]
    pp = max(y[S_PP], 0.0)
    ptank = prm[PTANK]
    dpl = prm[DP_LAM]
    # Load-sense pressure: the feeding port of every spool that is commanded open; with
    # every spool closed, the LS line's own pressure, draining through the bleed.
    pls = 0.0
    opened = False
    for j in range(N_LOOPS):
        s = clip(spools[j], -1.0, 1.0)
        if s > 0.0:
            pls = max(pls, y[S0 + NS * j + X_PA])
            opened = True
        elif s < 0.0:
            pls = max(pls, y[S0 + NS * j + X_PB])
            opened = True
    if opened:
        dy[S_LS] = (pls - y[S_LS]) / LS_TRACK_S
    else:
        pls = max(y[S_LS], ptank)
        dy[S_LS] = -prm[LS_BLEED] * (pls - ptank) * prm[BETA] / prm[V_LS]
    fg = chain_forces(
        y[S0 + X_X], y[S0 + NS + X_X], y[S0 + 2 * NS + X_X], y[S0 + NS + X_V],
        y[S0 + 2 * NS + X_V], payload, dig, _chain(prm),
    )  # fmt: skip
    q_supply = 0.0
    for j in range(N_LOOPS):
        b = S0 + NS * j
        p = LOOP0 + NL * j
        pa = max(y[b + X_PA], 0.0)
        pb = max(y[b + X_PB], 0.0)
        x = y[b + X_X]
        v = y[b + X_V]
        s, o_pos, o_neg = _opening(spools[j], lims[j], underlaps[j])
        kv = prm[p + P_KV]
        # Compensated meter-in: the drop is PP - max(PLS, port); the load-holding check
        # closes the edge when the port is above the compensator's outlet.
        dpa = pp - max(pls, pa)
        dpb = pp - max(pls, pb)
        q_pa = orifice(kv * o_pos, dpa, dpl) if dpa > 0.0 else 0.0
        q_pb = orifice(kv * o_neg, dpb, dpl) if dpb > 0.0 else 0.0
        q_bt = orifice(kv * o_pos, pb - ptank, dpl)
        q_at = orifice(kv * o_neg, pa - ptank, dpl)
        q_il = leaks[j] * (pa - pb)
        aa = prm[p + P_AA]
        ab = prm[p + P_AB]
        if j == SWING:
            q_il += prm[MOTOR_LEAK] * (pa - pb)
            dpx = pa - pb
            if dpx > prm[XR_CRACK]:
                q_il += prm[XR_GAIN] * (dpx - prm[XR_CRACK])
            elif -dpx > prm[XR_CRACK]:
                q_il -= prm[XR_GAIN] * (-dpx - prm[XR_CRACK])
            vol_a = prm[p + P_V0A]
            vol_b = prm[p + P_V0B]
            dy[b + X_V] = (aa * pa - ab * pb - prm[p + P_CVISC] * v) / prm[p + P_MASS]
        else:
            stroke = prm[p + P_STROKE]
            drive = pa * aa - pb * ab - fg[j]
            if (x <= 0.0 and v <= 0.0 and drive <= 0.0) or (
                x >= stroke and v >= 0.0 and drive >= 0.0
            ):
                v = 0.0
                dy[b + X_V] = 0.0
            else:
                dy[b + X_V] = (drive - prm[p + P_CVISC] * v) / prm[p + P_MASS]
            vol_a = prm[p + P_V0A] + aa * x
            vol_b = prm[p + P_V0B] + ab * (stroke - x)
        dy[b + X_X] = v
        dy[b + X_PA] = (q_pa - q_at - q_il - aa * v) * prm[BETA] / vol_a
        dy[b + X_PB] = (q_pb - q_bt + q_il + ab * v) * prm[BETA] / vol_b
        aux[AUX_Q0 + j] = q_pa + q_pb
        q_supply += q_pa + q_pb
    # The LS pump: proportional regulator, pressure cut-off, leakage of a worn pump.
    disp = clip((pls + prm[LS_MARGIN] - pp) / prm[LS_BAND], 0.0, 1.0)
    disp *= clip((prm[CUT_FULL] - pp) / (prm[CUT_FULL] - prm[CUT_START]), 0.0, 1.0)
    qp = disp * prm[DISP_MAX] * speed_rps - (prm[PUMP_LEAK] + pump_leak) * pp
    q_relief = prm[RELIEF_GAIN] * max(pp - prm[RELIEF_CRACK], 0.0)
    dy[S_PP] = (qp - q_relief - q_supply) * prm[BETA] / prm[V_LINE]
    aux[AUX_QP] = qp
    aux[AUX_PLS] = pls


@jit(inline="always")
def _project(y: np.ndarray, prm: np.ndarray) -> None:
    """No port below tank (the make-up checks), rods within their stops."""
    if y[S_PP] < 0.0:
        y[S_PP] = 0.0
    for j in range(N_LOOPS):
        b = S0 + NS * j
        if y[b + X_PA] < 0.0:
            y[b + X_PA] = 0.0
        if y[b + X_PB] < 0.0:
            y[b + X_PB] = 0.0
        if j == SWING:
            continue
        stroke = prm[LOOP0 + NL * j + P_STROKE]
        if y[b + X_X] < 0.0:
            y[b + X_X] = 0.0
            y[b + X_V] = max(y[b + X_V], 0.0)
        elif y[b + X_X] > stroke:
            y[b + X_X] = stroke
            y[b + X_V] = min(y[b + X_V], 0.0)


@jit(inline="always")
def _record(
    rec: np.ndarray,
    r: int,
    y: np.ndarray,
    u: np.ndarray,
    prm: np.ndarray,
    dy: np.ndarray,
    aux: np.ndarray,
) -> None:
    rhs(y, u, prm, dy, aux)
    rec[r, R_PP] = y[S_PP]
    rec[r, R_QP] = aux[AUX_QP]
    rec[r, R_LS] = aux[AUX_PLS]
    for j in range(N_LOOPS):
        b = S0 + NS * j
        c = R0 + NR * j
        rec[r, c] = y[b + X_PA]
        rec[r, c + 1] = y[b + X_PB]
        rec[r, c + 2] = aux[AUX_Q0 + j]
        rec[r, c + 3] = y[b + X_X]
        rec[r, c + 4] = y[b + X_V]


@jit
def integrate(
    y0: np.ndarray,
    inputs: np.ndarray,
    n_sub: int,
    input_dt: float,
    prm: np.ndarray,
    record_every: int,
) -> np.ndarray:
    """Classic RK4 at h = input_dt / n_sub, inputs linear between their samples (the
    integrator the boom loop shares, ``monitor.sim.rk4.integrate``); a row every
    ``record_every`` steps."""
    return rk4.integrate(
        rhs, _project, _record, N_RECORD, N_AUX, y0, inputs, n_sub, input_dt, prm, record_every
    )
