"""Which readings are late, and what the lateness is (``judge/delays.split``,
``diagnose/timing.py``): sensor dynamics delay the reading, not the machine; a delay every
reading shares, the rod included, is the recording's timing; a compliance of the lines
moves the chamber pressures together.

By hand first (delays chosen so the answer follows from the rule), then `monitor gap`'s
diagnosis of short simulated recordings with RodPos: PA read 30 ms late and nothing else; every
reading, the rod included, 15 ms late; a soft hose."""

from __future__ import annotations

import numpy as np
import pytest

from monitor.gap.diagnose import diagnose
from monitor.gap.fit.calibrate import apply
from monitor.gap.judge import delays
from monitor.gap.report.document import build_report
from monitor.gap.report.summary import summary_text
from monitor.io.recording import Recording
from monitor.sim.cycles import make_cycle
from monitor.sim.effects import Effect
from monitor.sim.machine import load_machine
from monitor.sim.simulate import simulate

M = load_machine()


def test_one_reading_later_than_the_rod_is_a_sensor_and_the_rest_share_their_delay():
    sp = delays.split({"PP": 1.0, "PA": 31.0, "PB": -1.0, "QP": 0.0, "RodVel": 2.0})
    assert sp is not None and sp.reference == "rod" and sp.late == ("PA",)
    assert sp.some_late and not sp.shared
    # What the on-time readings and the rod share: the median of 1, -1, 0, 2.
    assert sp.shared_ms == pytest.approx(0.5)


def test_every_reading_as_late_as_the_rod_is_a_shared_delay():
    sp = delays.split({"PP": 14.0, "PA": 16.0, "PB": 15.0, "QP": 19.0, "RodVel": 12.0})
    assert sp is not None and sp.late == () and not sp.some_late
    assert sp.shared and sp.shared_ms == pytest.approx(15.0)
    # A slow spool's 40 ms is the machine's, not the recording's: no timing note.
    slow = delays.split({"PP": 40.0, "PA": 42.0, "PB": 38.0, "QP": 41.0, "RodVel": 40.0})
    assert slow is not None and not slow.shared and not slow.some_late


def test_the_chambers_late_together_and_all_readings_late_are_not_read_as_some_sensors():
    # Air or a soft hose delays PA and PB: the oil, not necessarily their transducers.
    chambers = delays.split({"PP": 11.0, "PA": 34.0, "PB": 32.0, "QP": 13.0, "RodVel": 13.0})
    assert chambers is not None and chambers.late == ("PA", "PB") and not chambers.some_late
    hose = delays.split({"PP": 22.0, "PA": 31.0, "PB": 30.0, "QP": 27.0, "RodVel": 14.0})
    assert hose is not None and hose.late == ("PA", "PB", "QP") and not hose.some_late
    # All four later than the rod: the catalogue's all-readings lag (``check_timing``).
    four = delays.split({"PP": 50.0, "PA": 50.0, "PB": 52.0, "QP": 48.0, "RodVel": 12.0})
    assert four is not None and len(four.late) == 4 and not four.some_late and not four.shared
    # Without a rod the reference is the readings' median: one late reading stands out.
    no_rod = delays.split({"PP": 0.0, "PA": 0.0, "PB": 0.0, "QP": 25.0})
    assert no_rod is not None and no_rod.reference == "readings" and no_rod.late == ("QP",)


COMMANDS = ("SpoolCmd", "PumpDispCmd", "EngineSpeed", "OilTemp")


def _recording(
    effects: list[Effect],
    seed: int,
    late_ms: dict[str, float],
    all_late_ms: float = 0.0,
    displacement: float = 1.0,
) -> Recording:
    """60 s of boom cycles on a machine a few percent off nominal, RodPos measured, the
    engine speed with a white ripple; the columns of ``late_ms`` read that many ms late
    (whole samples: a shift, no filter), and every reading ``all_late_ms`` late against the
    commands logged beside them (the machine driven by the commands that much later: the
    same for a time-invariant machine, in continuous time); the pump's displacement
    ``displacement`` times the configured one (a tolerance the calibration does not fit)."""
    cmd = make_cycle("boom", 60.0, seed)
    cols = dict(cmd.columns)
    rng = np.random.default_rng(seed + 1000)
    cols["EngineSpeed"] = cols["EngineSpeed"] + rng.normal(0.0, 5.0, len(cmd))
    logged = {n: cols[n].copy() for n in COMMANDS}
    for n in COMMANDS:
        cols[n] = np.interp(cmd.t - all_late_ms / 1e3, cmd.t, cols[n])
    machine = apply(M, {"mass": 1.04, "gravity_load": 0.97, "volumes": 1.03})
    machine = machine.with_changes(pump_disp_m3_rev=displacement * M.pump.pump_disp_m3_rev)
    rec = simulate(Recording(cmd.t, cols, cmd.source), machine, effects=effects, seed=seed)
    drop = ("RodPosTrue", "RodVel", "SpoolPos")
    cols = {n: v for n, v in rec.columns.items() if n not in drop} | logged
    for name, ms in late_ms.items():
        k = int(round(ms / 10.0))
        cols[name] = np.concatenate([np.full(k, cols[name][0]), cols[name][:-k]])
    return Recording(rec.t, cols, "sim")


def test_pa_read_30_ms_late_is_a_sensor_lag_on_pa():
    d = diagnose(_recording([], 41, {"PA": 30.0}), M)
    rep = build_report(d, M)
    assert rep["verdict"] == "sensor_lag"
    assert rep["params"]["sensor_lag"]["signals"] == ["PA"]
    assert rep["params"]["delay_ms"]["value"] == pytest.approx(30.0, abs=3.0)
    t = rep["timing"]
    assert t["late_signals"] == ["PA"] and t["sensor_lag_on_late"]["named"] is True
    assert t["sensor_lag_on_late"]["heldout_reduction"] >= 0.5
    assert rep["mechanism"]["name"] == "sensor reading on PA"
    assert "PA read 30 ms late" in summary_text(rep)


def test_every_reading_15_ms_late_is_none_with_a_timing_note():
    d = diagnose(_recording([], 42, {}, all_late_ms=15.0), M)
    rep = build_report(d, M)
    assert rep["verdict"] == "none"
    t = rep["timing"]
    assert t["late_signals"] == [] and t["shared_ms"] == pytest.approx(15.0, abs=4.0)
    # Each reading re-timed by its delay fitted on the calibration part (1 ms grid): the
    # tolerance calibration takes a little of the pressures' delay (larger volumes build
    # pressure later), so they fit a few ms short of 15.
    fitted = t["retimed"]["delays_ms"]
    assert np.median(list(fitted.values())) == pytest.approx(15.0, abs=3.0)
    assert all(10.0 <= v <= 20.0 for v in fitted.values())
    assert t["retimed"]["heldout_reduction"] >= 0.5
    assert "ms late" in t["decided_by"] and "not a fault" in t["decided_by"]
    assert rep.get("mechanism") is None  # none names no mechanism


def test_a_soft_hose_is_not_a_sensor_lag():
    rec = _recording([Effect.make("hose_compliance", wall_modulus_gpa=0.3)], 43, {})
    rep = build_report(diagnose(rec, M), M)
    assert rep["verdict"] != "sensor_lag"
    t = rep.get("timing") or {}
    assert not (t.get("sensor_lag_on_late") or {}).get("named", False)


def test_a_pump_10_pct_large_and_every_reading_late_is_none_with_the_tolerance_said():
    # A healthy machine of another make: its pump 10 % larger than configured (within the
    # 15 % band the calibration grants the valve's gain, but not fitted by it) and every
    # reading 15 ms late.  Only the displacement's term explains what is left (the
    # calibration cannot: it has no pump), so it is suggested alone, without a delay
    # beside it: `unexplained` before 2026-11-29 (the third plant's s336080_65, +-12 %).
    d = diagnose(_recording([], 42, {}, all_late_ms=15.0, displacement=1.10), M)
    rep = build_report(d, M)
    assert rep["verdict"] == "none"
    t = rep["timing"]
    assert t["verdict_without_check"] == "unexplained" and t["retimed"]["gain_share"] >= 0.95
    (term,) = t["tolerance_terms"]
    assert (term["term"], term["signal"]) == ("pump_setting", "displacement")
    # The simulator's +10 %, read within 2 % (the calibrated valve gain and volumes take a
    # little of it).
    assert term["coefficient"] == pytest.approx(10.0, abs=2.0)
    assert "a tolerance" in t["decided_by"] and "not a fault" in t["decided_by"]
