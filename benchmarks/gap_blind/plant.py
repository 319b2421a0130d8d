"""Reference boom loop (docs/reference/contracts.md), own physics, fixed-step numba integrator.

Textbook sources: Merritt (1967) orifice and chamber pressure equations; Jelali & Kroll (2003)
valve/pump models; Canudas de Wit et al. (1995) LuGre; Armstrong-Helouvry (1994) Stribeck;
ASTM D341 Walther viscosity; entrained air mixture law (Yu 1994, Gholizadeh 2011 review).
All quantities SI inside.  Parameters travel in one float array indexed by the names in P.
"""

from __future__ import annotations

import numpy as np
from numba import njit

NAMES = (
    "mass_kg",
    "gravity_N",
    "visc_Nspm",
    "kv",
    "va0_m3",
    "vb0_m3",
    "vp_m3",
    "bulk_Pa",
    "ac_m2",
    "ar_m2",
    "stroke_m",
    "disp_m3",
    "comp_lo_Pa",
    "comp_hi_Pa",
    "relief_lo_Pa",
    "relief_hi_Pa",
    "relief_q_m3s",
    # effect switches (0 = off) and parameters
    "fric_mode",
    "fc_N",
    "fs_N",
    "vs_mps",
    "sigma0",
    "sigma1",
    "air_mode",
    "air_frac",
    "air_n",
    "air_pdiss_Pa",
    "visc_mode",
    "visc_ratio0",
    "visc_ratio1",
    "leak_pump",
    "leak_seal",
    "leak_valve",
    "spool_mode",
    "spool_wn",
    "spool_zeta",
    "spool_tau",
    "spool_rate",
    "db_mode",
    "db_overlap",
    "pump_mode",
    "pump_tau",
    "pump_wn",
    "pump_zeta",
    "hose_mode",
    "hose_bulk_Pa",
    "hose_c_m3pPa",
    "load_mode",
    "load_k",
    "load_theta0",
    "load_dtheta",
    "ooc_mode",
    "ooc_amp",
    "ooc_freq",
    "ooc_leak",
    "ooc_comp_shift_Pa",
    "duration_s",
)
P = {n: i for i, n in enumerate(NAMES)}
BAR = 1e5
LPM = 1.0 / 60000.0


def nominal() -> np.ndarray:
    """The reference machine (docs/reference/contracts.md) as a parameter vector (SI)."""
    p = np.zeros(len(NAMES))
    ac = np.pi / 4 * 0.063**2
    ar = ac - np.pi / 4 * 0.036**2
    vals = dict(
        mass_kg=400.0,
        gravity_N=6000.0,
        visc_Nspm=2000.0,
        kv=20 * LPM / np.sqrt(10 * BAR),
        va0_m3=0.3e-3,
        vb0_m3=0.3e-3,
        vp_m3=0.5e-3,
        bulk_Pa=1.5e9,
        ac_m2=ac,
        ar_m2=ar,
        stroke_m=0.5,
        disp_m3=11e-6,
        comp_lo_Pa=190 * BAR,
        comp_hi_Pa=200 * BAR,
        relief_lo_Pa=210 * BAR,
        relief_hi_Pa=220 * BAR,
        relief_q_m3s=40 * LPM,
        visc_ratio0=1.0,
        visc_ratio1=1.0,
        air_n=1.0,
        duration_s=300.0,
    )
    for k, v in vals.items():
        p[P[k]] = v
    return p


@njit(cache=True)
def _orifice(k, x, dp):
    # Q = k x sqrt(dp), laminarised below 0.2 bar so the derivative stays finite
    return k * x * dp / np.sqrt(abs(dp) + 0.2e5)


@njit(cache=True)
def simulate(p, spool_pct, disp_pct, speed_rpm, temp_c, dt, sub):
    """Integrate the loop; commands sampled every dt*sub; returns (n, 6) PP,PA,PB,QP,x,v."""
    n = spool_pct.shape[0]
    out = np.zeros((n, 6))
    x, v, pp, pa, pb, z = 0.05, 0.0, 20e5, 40e5, 10e5, 0.0
    xs, vs, ds, dds = 0.0, 0.0, disp_pct[0] / 100.0, 0.0
    m, g0, cv, kv = p[0], p[1], p[2], p[3]
    ac, ar, L = p[8], p[9], p[10]
    t = 0.0
    for i in range(n):
        u = spool_pct[i] / 100.0
        dcmd = disp_pct[i] / 100.0
        w = speed_rpm[i] / 60.0
        for _ in range(sub):
            t += dt
            # oil viscosity ratio nu_ref/nu(T) interpolated across the recording
            frac = t / p[56]
            vr = p[28] + (p[29] - p[28]) * min(frac, 1.0)
            # spool
            if p[33] == 1.0:
                acc = p[34] ** 2 * (u - xs) - 2 * p[35] * p[34] * vs
                vs += acc * dt
                xs += vs * dt
            elif p[33] == 2.0:
                rate = (u - xs) / p[36]
                rate = max(-p[37], min(p[37], rate))
                xs += rate * dt
            else:
                xs = u
            xs = max(-1.0, min(1.0, xs))
            # metering opening, with overlap
            op = xs
            if p[38] == 1.0:
                d = p[39]
                op = np.sign(xs) * max(abs(xs) - d, 0.0) / (1 - d)
            elif p[38] == 2.0:
                d = p[39]
                e = max(abs(xs) - d, 0.0) / (1 - d)
                op = np.sign(xs) * e * e * (3 - 2 * min(e, 1.0)) if e < 1 else np.sign(xs)
            # compensator destrokes; the swashplate follows with the pump's control dynamics
            clo = p[12] + p[55]
            chi = p[13] + p[55]
            comp = min(1.0, max(0.0, (chi - pp) / (chi - clo)))
            target = dcmd * comp
            if p[40] == 1.0:
                ds += (target - ds) / p[41] * dt
            elif p[40] == 2.0:
                dds += (p[42] ** 2 * (target - ds) - 2 * p[43] * p[42] * dds) * dt
                ds += dds * dt
            else:
                ds = target
            leak_p = p[30] * vr * pp
            qpump = p[11] * max(ds, 0.0) * w - leak_p
            qrel = p[16] * min(1.0, max(0.0, (pp - p[14]) / (p[15] - p[14])))
            # valve flows
            if op >= 0:
                qpa = _orifice(kv, op, pp - pa)
                qbt = _orifice(kv, op, pb)
                qa, qb, qp_out = qpa, -qbt, qpa
            else:
                qpb = _orifice(kv, -op, pp - pb)
                qat = _orifice(kv, -op, pa)
                qa, qb, qp_out = -qat, qpb, qpb
            # valve clearance leakage (closed centre, laminar), seal leakage A->B
            lv = p[32] * vr
            qa += lv * ((pp - pa) - pa)
            qb += lv * ((pp - pb) - pb)
            qp_out += lv * ((pp - pa) + (pp - pb))
            qs = p[31] * vr * (pa - pb)
            qa -= qs
            qb += qs
            if p[51] == 2.0:  # out of catalogue: A leaks to tank, growing with pressure
                qa -= p[54] * pa * pa / 1e7
            # forces
            visc = cv
            if p[27] != 0.0:
                visc = cv / max(vr, 0.2) ** 0.5
            ff = visc * v
            if p[17] == 1.0:
                fc, fs, vsx = p[18], p[19], p[20]
                ff += (fc + (fs - fc) * np.exp(-((v / vsx) ** 2))) * np.tanh(v / 1e-3)
            elif p[17] == 2.0:
                fc, fs, vsx, s0, s1 = p[18], p[19], p[20], p[21], p[22]
                gv = (fc + (fs - fc) * np.exp(-((v / vsx) ** 2))) / s0
                dz = v - abs(v) * z / gv
                z += dz * dt
                ff += s0 * z + s1 * dz
            grav = g0
            if p[47] == 1.0:
                grav = g0 * (1 + p[48] * (x / L - 0.5))
            elif p[47] == 2.0:
                th = p[49] + p[50] * x / L
                grav = g0 * np.cos(th) / np.cos(p[49] + 0.5 * p[50])
            if p[51] == 1.0:
                grav += p[52] * np.sin(2 * np.pi * p[53] * t)
            fst = 0.0
            if x < 0.0:
                fst = -5e7 * x - 2e5 * v
            elif x > L:
                fst = -5e7 * (x - L) - 2e5 * v
            a = (pa * ac - pb * ar - grav - ff + fst) / m
            v += a * dt
            x += v * dt
            # chamber stiffness
            va = p[4] + ac * x
            vb = p[5] + ar * (L - x)
            ba = _beff(p, pa)
            bb = _beff(p, pb)
            bp = _beff(p, pp)
            ca = va / ba + (p[46] if p[44] == 2.0 else 0.0)
            cb = vb / bb + (p[46] if p[44] == 2.0 else 0.0)
            pa += (qa - ac * v) / ca * dt
            pb += (qb + ar * v) / cb * dt
            pp += (qpump - qrel - qp_out) / (p[6] / bp) * dt
            pa, pb, pp = max(pa, 0.0), max(pb, 0.0), max(pp, 0.0)
        out[i, 0], out[i, 1], out[i, 2] = pp, pa, pb
        out[i, 3], out[i, 4], out[i, 5] = qpump, x, v
    return out


@njit(cache=True)
def _beff(p, pr):
    b0 = p[7]
    pa = max(pr, 1e5)
    if p[23] != 0.0:
        a0, nn = p[24], p[25]
        if p[23] == 2.0:  # free air dissolves linearly (Henry) until p_diss
            a0 = a0 * max(0.0, 1.0 - (pa - 1e5) / (p[26] - 1e5))
        r = a0 * (1e5 / pa) ** (1.0 / nn)
        b0 = ((1 - a0) + r) / ((1 - a0) / b0 + r / (nn * pa))
    if p[44] == 1.0:
        b0 = 1.0 / (1.0 / b0 + 1.0 / p[45])
    return b0
