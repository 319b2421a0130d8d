"""One recording of the fifth plant from its key entry: machine, effect, duty cycle, plant
run, sensors, CSV text. Everything is drawn from the entry's own seed, so the key rebuilds
the file byte for byte."""

from __future__ import annotations

import io

import numpy as np

from benchmarks.gap_fifth import cycle as cy
from benchmarks.gap_fifth import effects as ef
from benchmarks.gap_fifth import params as pr
from benchmarks.gap_fifth import plant as pl
from benchmarks.gap_fifth import sensors as se

COLUMNS = ("t", "SpoolCmd", "PumpDispCmd", "EngineSpeed", "OilTemp", "PP", "PA", "PB", "QP")
FORMATS = ("%.4f", "%.1f", "%.1f", "%.3f", "%.0f", "%.2f", "%.2f", "%.2f", "%.2f")


def commands(rng: np.random.Generator, n_ms: int, warm: cy.Warmup) -> pl.Commands:
    """The operator's commands and the machine's surroundings, one value a millisecond."""
    spool = cy.spool_profile(rng, n_ms)
    disp = cy.blocks(rng, n_ms, 1.0, lambda: round(rng.uniform(0.55, 0.9), 2), 0.25)
    rpm = cy.blocks(rng, n_ms, cy.RPM_NOMINAL, lambda: round(rng.uniform(1850, 2100)), 0.2)
    rpm = cy.slew(rpm - cy.RPM_NOMINAL, 0.3) + cy.RPM_NOMINAL  # 300 rpm/s
    temp = warm.at(np.arange(n_ms) / 1000.0)
    return pl.Commands(spool, disp, rpm, temp, cy.disturbance(rng, n_ms))


def simulate(entry: dict, duration_s: float) -> tuple[dict[str, np.ndarray], dict]:
    """The recording's columns (contract names, RodPos when the entry has it), and what
    the key says about it (the effect's parameters, the oil temperature's span)."""
    rng = np.random.default_rng(entry["seed"])
    # keys written before the compensated pump name no pump: theirs was load sensing
    values = pr.machine(rng, entry["band_pct"] / 100.0, entry.get("pump", "ls"))
    sensors = se.healthy_spread(rng)
    warm = cy.draw_warmup(rng)
    change = ef.apply(rng, entry["kind"], entry["name"], values, sensors, warm, entry.get("signal"))
    v = change.values
    n_ms = int(round(duration_s * 1000)) + 20
    cmd = commands(rng, n_ms, change.warm)
    nu = pr.viscosity_cst(cmd.temp_c, v["nu40_cst"], v["vogel_b_k"], v["vogel_c_k"])
    true = pl.run(v, cmd, nu, stroke0_m=rng.uniform(0.05, 0.45))
    t = se.sample_times(rng, duration_s)
    s = change.sensors
    cols = {
        "t": t,
        "SpoolCmd": np.round(np.interp(t * 1000, np.arange(n_ms), cmd.spool) * 1000) / 10,
        "PumpDispCmd": np.round(np.interp(t * 1000, np.arange(n_ms), cmd.disp) * 1000) / 10,
        "EngineSpeed": se.engine_speed(rng, true["speed_rad_s"], t),
        "OilTemp": se.oil_temp(cmd.temp_c, t, rng.uniform(-0.5, 0.5)),
        "PP": se.pressure(rng, true["pp"], t, "PP", s),
        "PA": se.pressure(rng, true["pa_port"], t, "PA", s),
        "PB": se.pressure(rng, true["pb_port"], t, "PB", s),
        "QP": se.flow(true["q_cum"], t, s),
    }
    if entry["rodpos"]:
        cols["RodPos"] = se.rod_pos(rng, true["stroke"], t, s, v["stroke_m"] * 1000)
    info = {
        "params": change.params,
        "oil_temp_c": [round(change.warm.start_c, 1), round(float(cmd.temp_c[-1]), 1)],
    }
    return cols, info


def csv_text(cols: dict[str, np.ndarray]) -> str:
    """The contract CSV (header, one row every 10 ms)."""
    names = list(COLUMNS) + (["RodPos"] if "RodPos" in cols else [])
    fmts = list(FORMATS) + (["%.1f"] if "RodPos" in cols else [])
    table = np.column_stack([cols[n] for n in names])
    buf = io.StringIO()
    np.savetxt(buf, table, fmt=fmts, delimiter=",", header=",".join(names), comments="")
    return buf.getvalue().replace("-0.00,", "0.00,").replace(",-0.0,", ",0.0,")


def build(entry: dict, duration_s: float) -> tuple[bytes, dict]:
    """The recording's file content, and what the key says about it."""
    cols, info = simulate(entry, duration_s)
    return csv_text(cols).encode("ascii"), info
