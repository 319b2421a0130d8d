"""Where the simulator departs from the recording: per signal, operating regime, frequency
band and time window, each ranked worst first.

All of it works on the normalised residual (simulated - measured) / std(measured) of the
tolerance-calibrated nominal simulator over every scored sample.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.signal import coherence, welch

from monitor.gap.data.prepare import Prepared
from monitor.gap.data.segments import Segment
from monitor.signals import MEASURED_NAMES, SAMPLE_RATE_HZ

BANDS_HZ: tuple[tuple[float, float], ...] = (
    (0.0, 0.5),
    (0.5, 2.0),
    (2.0, 5.0),
    (5.0, 15.0),
    (15.0, 50.0),
)
WINDOW_S = 2.0
N_WINDOWS = 5
#: Regimes rarer than this share of the time are not ranked (too few samples).
MIN_REGIME_SHARE = 0.02
TRANSIENT_S = 0.5
REVERSAL_S = 0.5


def scored_mask(n: int, segments: Sequence[Segment]) -> np.ndarray:
    mask = np.zeros(n, dtype=bool)
    for seg in segments:
        mask[seg.scored] = True
    return mask


def _near(events: np.ndarray, n: int, half_rows: int) -> np.ndarray:
    """Rows within ``half_rows`` of any event row."""
    mark = np.zeros(n + 1)
    for e in np.flatnonzero(events).tolist():  # Python ints
        mark[max(e - half_rows, 0)] += 1
        mark[min(e + half_rows + 1, n)] -= 1
    return np.cumsum(mark[:-1]) > 0


def regimes(prep: Prepared) -> dict[str, np.ndarray]:
    """Operating regimes as row masks, in families whose masks partition the recording."""
    n = len(prep)
    rate = SAMPLE_RATE_HZ
    spool = prep.cmd["SpoolCmd"]
    pp = np.nan_to_num(prep.meas["PP"])
    temp = prep.cmd["OilTemp"]
    vel = np.gradient(prep.rod_mm) * rate
    moving = np.abs(vel) > 5.0  # mm/s
    direction = np.sign(vel) * moving
    last = 0.0
    flips = np.zeros(n, dtype=bool)
    for i, d in enumerate(direction):  # a reversal: the sign changes across a still spell
        if d != 0:
            flips[i] = last != 0 and d != last
            last = d
    changes = np.abs(np.diff(spool, prepend=spool[0])) > 0.5
    transient = _near(changes, n, int(TRANSIENT_S * rate))
    centre = np.abs(spool) < 5.0
    return {
        "pump pressure < 50 bar": pp < 50,
        "pump pressure 50-150 bar": (pp >= 50) & (pp < 150),
        "pump pressure >= 150 bar": pp >= 150,
        "spool near centre (|SpoolCmd| < 5 %)": centre,
        "spool open": ~centre,
        "cylinder velocity reversal (+-0.5 s)": _near(flips, n, int(REVERSAL_S * rate)),
        "no reversal": ~_near(flips, n, int(REVERSAL_S * rate)),
        "transient (< 0.5 s after a command change)": transient,
        "steady": ~transient,
        "oil < 40 degC": temp < 40,
        "oil 40-60 degC": (temp >= 40) & (temp < 60),
        "oil >= 60 degC": temp >= 60,
    }


def _sq(resid: dict[str, np.ndarray]) -> np.ndarray:
    return sum(np.nan_to_num(resid[n]) ** 2 for n in MEASURED_NAMES)


def by_signal(resid: dict[str, np.ndarray], mask: np.ndarray) -> list[dict]:
    out = [
        {"name": n, "nrmse": round(float(np.sqrt(np.nanmean(resid[n][mask] ** 2))), 5)}
        for n in MEASURED_NAMES
    ]
    return sorted(out, key=lambda d: -d["nrmse"])


def by_regime(prep: Prepared, resid: dict[str, np.ndarray], mask: np.ndarray) -> list[dict]:
    """Share of the squared residual per regime, its time share and their ratio."""
    sq = _sq(resid)
    total = float(sq[mask].sum())
    out = []
    for name, rmask in regimes(prep).items():
        m = rmask & mask
        time_share = float(m.sum() / max(mask.sum(), 1))
        if time_share < MIN_REGIME_SHARE or total <= 0:
            continue
        share = float(sq[m].sum() / total)
        out.append(
            {
                "regime": name,
                "share": round(share, 4),
                "time_share": round(time_share, 4),
                "concentration": round(share / time_share, 3),
                "nrmse": {
                    n: round(float(np.sqrt(np.nanmean(resid[n][m] ** 2))), 5)
                    for n in MEASURED_NAMES
                },
            }
        )
    return sorted(out, key=lambda d: -d["concentration"])


def by_band(prep: Prepared, resid: dict[str, np.ndarray]) -> list[dict]:
    """Residual power per frequency band (all signals) and its coherence with SpoolCmd."""
    fs = SAMPLE_RATE_HZ
    nper = 256
    spool = prep.cmd["SpoolCmd"]
    power = np.zeros(len(BANDS_HZ))
    coh = np.zeros(len(BANDS_HZ))
    for n in MEASURED_NAMES:
        r = np.nan_to_num(resid[n])
        f, pxx = welch(r, fs=fs, nperseg=nper)
        fc, cxy = coherence(r, spool, fs=fs, nperseg=nper)
        for i, (lo, hi) in enumerate(BANDS_HZ):
            sel = (f >= lo) & (f < hi) if hi < fs / 2 else (f >= lo)
            power[i] += float(pxx[sel].sum())
            coh[i] += float(np.mean(cxy[sel])) * float(pxx[sel].sum())
    total = power.sum()
    out = [
        {
            "band_hz": [lo, hi],
            "share": round(float(power[i] / total), 4) if total > 0 else 0.0,
            "coherence_spool": round(float(coh[i] / power[i]), 3) if power[i] > 0 else 0.0,
        }
        for i, (lo, hi) in enumerate(BANDS_HZ)
    ]
    return sorted(out, key=lambda d: -d["share"])


def spectra(resid: dict[str, np.ndarray]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Welch power spectral density of each signal's normalised residual (per Hz)."""
    out = {}
    f = np.zeros(0)
    for n in MEASURED_NAMES:
        f, out[n] = welch(np.nan_to_num(resid[n]), fs=SAMPLE_RATE_HZ, nperseg=256)
    return f, out


def worst_windows(prep: Prepared, resid: dict[str, np.ndarray], mask: np.ndarray) -> list[dict]:
    """The WINDOW_S windows carrying the largest share of the squared residual."""
    rows = int(WINDOW_S * SAMPLE_RATE_HZ)
    sq = np.where(mask, _sq(resid), 0.0)
    total = float(sq.sum())
    n_win = len(prep) // rows
    if n_win == 0 or total <= 0:
        return []
    per = sq[: n_win * rows].reshape(n_win, rows).sum(axis=1)
    out = []
    for w in np.argsort(per)[::-1][:N_WINDOWS]:
        sl = slice(w * rows, (w + 1) * rows)
        worst = max(MEASURED_NAMES, key=lambda n: float(np.nansum(resid[n][sl][mask[sl]] ** 2)))
        out.append(
            {
                "t_start": round(float(prep.t[sl.start] - prep.t[0]), 2),
                "t_end": round(float(prep.t[min(sl.stop, len(prep) - 1)] - prep.t[0]), 2),
                "share": round(float(per[w] / total), 4),
                "signal": worst,
            }
        )
    return out
