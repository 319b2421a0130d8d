"""Write the blind benchmark: contract CSVs and key.json.

    python -m benchmarks.gap_blind.generate OUT --seed S [--n-per-effect K] [--tolerance 5,15]

Seeds 1-99 are development seeds; the blind seed is chosen by the lead at scoring time.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from .formulations import EFFECTS, OUT_OF_CATALOGUE
from .plant import BAR, LPM, P, nominal, simulate

FS_HZ = 100.0
DRAWN = ("mass_kg", "va0_m3", "vb0_m3", "vp_m3", "kv", "gravity_N", "visc_Nspm")
NOISE = {"PP": 0.3, "PA": 0.3, "PB": 0.3, "QP": 0.1, "RodPos": 0.5}


def boom_cycle(rng: np.random.Generator, duration_s: float) -> np.ndarray:
    """SpoolCmd % at 100 Hz: raise/hold/lower/hold, amplitudes 40-100 %, phases 1-4 s,
    200 %/s rate limit."""
    n = int(duration_s * FS_HZ)
    target = np.zeros(n)
    i, k = 0, 0
    while i < n:
        sign = (1, 0, -1, 0)[k % 4]
        # lowering runs with gravity and is faster than raising: shorter lower phases keep
        # the boom off its bottom stop most of the time
        d = int(rng.uniform(1, 2) * FS_HZ) if sign < 0 else int(rng.uniform(1, 4) * FS_HZ)
        target[i : i + d] = sign * rng.uniform(40, 100)
        i, k = i + d, k + 1
    out = np.empty(n)
    y, step = 0.0, 200.0 / FS_HZ
    for j in range(n):
        y += float(np.clip(target[j] - y, -step, step))
        out[j] = y
    return out


def draw_machine(rng, tol):
    p = nominal()
    draw = {}
    for k in DRAWN:
        f = float(rng.uniform(1 - tol, 1 + tol))
        p[P[k]] *= f
        draw[k] = round(f, 4)
    return p, draw


def _lag(y, post):
    if post.get("lag") == "first_order":
        a = 1.0 / (1.0 + post["tau_s"] * FS_HZ)
        z = np.empty_like(y)
        z[0] = y[0]
        for i in range(1, len(y)):
            z[i] = z[i - 1] + a * (y[i] - z[i - 1])
        return z
    if post.get("lag") == "transport_delay":
        d = int(round(post["delay_s"] * FS_HZ))
        return np.concatenate([np.full(d, y[0]), y[:-d]]) if d else y
    return y


def record(p, post, rng, duration_s, temps, with_rodpos):
    """One recording as a dict of columns (contract units)."""
    spool = boom_cycle(rng, duration_s)
    n = spool.size
    disp = np.full(n, float(rng.uniform(85, 100)))
    speed = 2200 + rng.normal(0, 5, n)
    t = np.arange(n) / FS_HZ
    temp = np.interp(np.floor(t), [0, duration_s], temps)  # 1 Hz sample and hold
    p[P["duration_s"]] = duration_s
    o = simulate(p, spool, disp, speed, temp, 1e-4, 100)
    cols = {
        "PP": o[:, 0] / BAR,
        "PA": o[:, 1] / BAR,
        "PB": o[:, 2] / BAR,
        "QP": o[:, 3] / LPM,
        "RodPos": o[:, 4] * 1000,
    }
    for k in ("PP", "PA", "PB", "QP"):
        cols[k] = _lag(cols[k], post)
    for k, s in NOISE.items():
        cols[k] = cols[k] + rng.normal(0, s, n)
    sig = post.get("signal")
    if sig:
        cols[sig] = cols[sig] * post.get("gain", 1.0) + post.get("offset", 0.0)
    table = {
        "t": t,
        "SpoolCmd": spool,
        "PumpDispCmd": disp,
        "EngineSpeed": speed,
        "OilTemp": np.round(temp, 1),
        **cols,
    }
    if not with_rodpos:
        table.pop("RodPos")
    return table


def rodpos_column(rng, post: dict) -> bool:
    """Whether the recording carries RodPos: 70 % of them do; every one whose sensor error is
    on RodPos does (without the column the error cannot be seen: that recording is a
    healthy machine's).  One draw either way, so the other recordings stay the same."""
    drawn = bool(rng.random() > 0.3)
    return drawn or post.get("signal") == "RodPos"


def write_csv(path: Path, table: dict) -> None:
    names = list(table)
    data = np.column_stack([table[k] for k in names])
    np.savetxt(path, data, delimiter=",", header=",".join(names), comments="", fmt="%.4f")


def cases(n_per_effect: int):
    """(effect, formulation) list: every formulation, healthy, out of catalogue."""
    out = []
    for eff, forms in EFFECTS.items():
        names = list(forms)
        out += [(eff, names[i % len(names)]) for i in range(n_per_effect)]
    out += [("none", "healthy")] * n_per_effect
    names = list(OUT_OF_CATALOGUE)
    out += [("unexplained", names[i % len(names)]) for i in range(n_per_effect)]
    return out


def generate(
    out: Path, seed: int, n_per_effect: int, tolerances, duration_s=300.0, progress=True
) -> list[dict]:
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    keys = []
    todo = [(c, tol) for tol in tolerances for c in cases(n_per_effect)]
    for i, ((eff, form), tol) in enumerate(todo):
        p, draw = draw_machine(rng, tol / 100.0)
        temps = [float(rng.uniform(25, 40)), float(rng.uniform(60, 80))]
        post, expected = {}, None
        if eff in EFFECTS:
            post = EFFECTS[eff][form](rng, p, temps) or {}
        elif eff == "unexplained":
            fn, expected = OUT_OF_CATALOGUE[form]
            fn(rng, p, temps)
        with_rodpos = rodpos_column(rng, post)
        name = f"r{i:03d}_{eff}_{form}_tol{tol}.csv"
        write_csv(out / name, record(p, post, rng, duration_s, temps, with_rodpos))
        keys.append(
            {
                "file": name,
                "effect": eff,
                "formulation": form,
                "signal": post.get("signal"),
                "expected_suggestion": expected,
                "tolerance_pct": tol,
                "machine": draw,
                "oil_temp_c": temps,
                "rodpos": with_rodpos,
            }
        )
        if progress:
            print(f"[{i + 1}/{len(todo)}] {name}", file=sys.stderr, flush=True)
    (out / "key.json").write_text(json.dumps({"seed": seed, "recordings": keys}, indent=1))
    return keys


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.gap_blind.generate", description=__doc__.splitlines()[0]
    )
    ap.add_argument("out", type=Path)
    ap.add_argument(
        "--seed",
        type=int,
        required=True,
        help="1-99: development seeds; the blind seed is the lead's",
    )
    ap.add_argument("--n-per-effect", type=int, default=5)
    ap.add_argument("--tolerance", default="5,15", help="machine tolerances in %% (comma list)")
    ap.add_argument("--duration", type=float, default=300.0, help="seconds per recording")
    a = ap.parse_args(argv)
    try:
        tols = [float(x) for x in a.tolerance.split(",")]
    except ValueError:
        ap.error(f"--tolerance: not a comma list of numbers: {a.tolerance!r}")
    generate(a.out, a.seed, a.n_per_effect, tols, a.duration)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
