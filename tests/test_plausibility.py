"""Sensor plausibility: each check fires on its defect and names the right signal, stays
quiet on healthy data, and ``monitor detect`` and the per-tick path agree."""

from __future__ import annotations

import cantools
import naive
import numpy as np
import pytest
from live_support import tick_recording
from naive_frames import recording_from_candump

from monitor.config.settings import load_config
from monitor.detection.gating import GatingConfig
from monitor.detection.offline import detect
from monitor.detection.plausibility import (
    COLUMNS,
    DBC_RANGES,
    Plausibility,
    PlausibilityConfig,
    finding,
)
from monitor.detection.plausibility_config import (
    FrozenCheck,
    PumpSystem,
    RangeCheck,
    RelationCheck,
    RestCheck,
    StuckCheck,
)
from monitor.detection.ticker import Ticker
from monitor.io.recording import Recording
from monitor.resources import resource_path
from monitor.sim.cycles import make_cycle
from monitor.sim.machine import load_machine
from monitor.sim.simulate import simulate

CFG = load_config()
MACHINE = load_machine()


@pytest.fixture(scope="module")
def normal_run() -> Recording:
    return simulate(make_cycle("boom", 90.0, 4242), MACHINE, seed=4242)


def edited(rec: Recording, **cols: np.ndarray) -> Recording:
    out = {k: v.copy() for k, v in rec.columns.items()}
    out.update(cols)
    return Recording(rec.t, out, "edited", dict(rec.meta))


def findings_of(rec: Recording, cfg: PlausibilityConfig | None = None):
    """(sensor, check) -> first time (s) of every finding over the recording."""
    p = Plausibility(cfg or PlausibilityConfig(), CFG.alarm.min_engine_rpm)
    n = len(rec)
    x = np.column_stack([rec[c] if rec.has(c) else np.full(n, np.nan) for c in COLUMNS])
    check, sig = p.series(x)
    out: dict[tuple, float] = {}
    for i in np.flatnonzero(check):
        out.setdefault(finding(int(check[i]), int(sig[i])), round(float(rec.t[i]), 2))
    return out, check, sig


def idx(rec: Recording, t_s: float) -> int:
    return int(round((t_s - rec.t[0]) / 0.01))


def test_dbc_ranges_are_the_shipped_dbcs() -> None:
    db = cantools.database.load_file(str(resource_path("dbc", "monitor.dbc")))
    for name, (lo, hi) in DBC_RANGES.items():
        sig = next(s for m in db.messages for s in m.signals if s.name == name)
        assert (sig.minimum, sig.maximum) == (lo, hi), name


def test_healthy_runs_and_shipped_logs_raise_no_finding(normal_run) -> None:
    for log in ("normal.log", "piston_wear.log", "spool_stroke.log", "spool_wear.log"):
        rec = recording_from_candump(resource_path("replay", log))
        assert findings_of(rec)[0] == {}, log
    assert findings_of(normal_run)[0] == {}
    ramp = simulate(make_cycle("ramp", 80.0, 5), MACHINE, seed=5)
    assert findings_of(ramp)[0] == {}


def test_frozen_sensor_is_named_after_frozen_s(normal_run) -> None:
    qp = normal_run["QP"].copy()
    k = idx(normal_run, 30.0)
    qp[k:] = 12.34  # the filter output hangs on one value
    found, _, _ = findings_of(edited(normal_run, QP=qp))
    # 100 repeats of the value after its first sample: the 101st sample, t = 31.00 s
    assert found == {("QP", "frozen"): 31.0}


def _rows(n: int, spool: float, pp: float, pa: float, pb: float, qp: float) -> Recording:
    """``n`` samples of one steady state, engine running, oil warm; the pressures carry
    their sensors' noise (0.3 bar rms), QP is exactly ``qp`` throughout."""
    t = np.arange(n) * 0.01
    noise = np.random.default_rng(3).normal(0.0, 0.3, (3, n))
    cols = dict(SpoolCmd=spool, PumpDispCmd=80.0, EngineSpeed=1800.0, OilTemp=50.0, QP=qp)
    out = {k: np.full(n, float(v)) for k, v in cols.items()}
    out.update(PP=pp + noise[0], PA=pa + noise[1], PB=pb + noise[2])
    return Recording(t, out, "rows", {})


def test_a_flow_reading_pinned_at_zero_while_the_valve_passes_oil_is_frozen() -> None:
    # Spool 50 % open towards A, pump 60 bar above port A: oil flows through the metering
    # edge, so QP at exactly 0.00 L/min (its range limit) for 1 s is a hung sensor: the
    # finding at the 101st identical sample.  B fed the same way with a negative command.
    found, _, _ = findings_of(_rows(150, 50.0, 180.0, 120.0, 5.0, 0.0))
    assert found == {("QP", "frozen"): 1.0}
    found, _, _ = findings_of(_rows(150, -50.0, 180.0, 5.0, 120.0, 0.0))
    assert found == {("QP", "frozen"): 1.0}


@pytest.mark.parametrize(
    "spool, pp, pa, pb",
    [
        (50.0, 200.0, 195.0, 5.0),  # at the end stop: A has risen to the pump, no drop, no flow
        (10.0, 180.0, 120.0, 5.0),  # spool barely open (below relation_spool_pct)
        (-50.0, 180.0, 120.0, 175.0),
    ],  # fed port B at the pump (A high does not count)
)
def test_a_flow_reading_of_zero_without_flow_through_the_valve_is_not_frozen(
    spool: float, pp: float, pa: float, pb: float
) -> None:
    assert findings_of(_rows(300, spool, pp, pa, pb, 0.0))[0] == {}


def test_stuck_sensor_with_live_noise_is_named(normal_run) -> None:
    rng = np.random.default_rng(1)
    pa = normal_run["PA"].copy()
    k = idx(normal_run, 10.0)
    pa[k:] = 20.0 + rng.normal(0.0, 0.3, len(pa) - k)  # noise alive, no longer following
    rec = edited(normal_run, PA=pa)
    found, _, _ = findings_of(rec)
    assert list(found) == [("PA", "stuck")]
    # It fires once 20 s of moving samples (|SpoolCmd| >= 20 % or QP >= 2 L/min) passed in
    # band: count them by hand from the injection on.
    moving = (np.abs(rec["SpoolCmd"]) >= 20.0) | (rec["QP"] >= 2.0)
    k_fire = k + int(np.flatnonzero(np.cumsum(moving[k + 1 :]) >= 2000)[0]) + 1
    assert found[("PA", "stuck")] == pytest.approx(rec.t[k_fire], abs=0.02)
    # The same noise band on a moving sensor: no finding (20 s of motion in band is rare).
    assert findings_of(normal_run, PlausibilityConfig(stuck=StuckCheck(stuck_s=20.0)))[0] == {}


def test_out_of_range_value_is_named_and_clears(normal_run) -> None:
    pb = normal_run["PB"].copy()
    k = idx(normal_run, 20.0)
    pb[k : k + 50] = 450.0  # a CSV sample beyond the 0..400 bar sensor
    found, check, sig = findings_of(edited(normal_run, PB=pb))
    assert found == {("PB", "signal_range"): 20.09}  # range_s 0.1 = 10 samples
    assert check[k + 60] == 0  # back in range: the finding clears
    # Configured limits tighter than the DBC's: 250 bar on a 0..400 bar channel.
    pp = normal_run["PP"].copy()
    pp[k : k + 20] = 260.0
    pp[k + 20 : k + 40] = 249.99  # just below the limit is in range
    found, _, _ = findings_of(
        edited(normal_run, PP=pp), PlausibilityConfig(RangeCheck(pressure_max_bar=250))
    )
    assert found == {("PP", "signal_range"): 20.09}
    # At the limit a transducer is pinned at full scale: out of range.
    pp[k + 20 : k + 40] = 250.0
    cfg = PlausibilityConfig(RangeCheck(pressure_max_bar=250))
    found, check, _ = findings_of(edited(normal_run, PP=pp), cfg)
    assert found == {("PP", "signal_range"): 20.09} and check[k + 39] != 0


def test_port_reading_high_is_named_against_the_pump(normal_run) -> None:
    pa = normal_run["PA"] + 30.0  # a +30 bar offset on port A
    found, _, _ = findings_of(edited(normal_run, PA=pa))
    assert set(found) == {("PA", "pump_below_port")}
    # The first raise with the spool >= 20 % open, plus relation_s = 1 s of violation.
    spool = normal_run["SpoolCmd"]
    first_raise = int(np.flatnonzero(spool >= 20.0)[0])
    assert found[("PA", "pump_below_port")] >= normal_run.t[first_raise] + 0.99


def test_pump_reading_low_is_named_once_both_ports_show_it(normal_run) -> None:
    pp = normal_run["PP"] - 40.0
    found, check, sig = findings_of(edited(normal_run, PP=pp))
    assert ("PP", "pump_below_port") in found
    # First one port is seen above PP, later the other: from then on PP is named.
    assert found[("PP", "pump_below_port")] > min(
        found.get(("PA", "pump_below_port"), np.inf), found.get(("PB", "pump_below_port"), np.inf)
    )
    assert finding(int(check[-1]), int(sig[-1])) == ("PP", "pump_below_port")


def rest_then_run(run: Recording, pa_rest_bar: float, pb_rest_bar: float = 0.0) -> Recording:
    """40 s engine off, spool centred, PA at ``pa_rest_bar``, then ``run``."""
    n_rest = 4000
    rng = np.random.default_rng(3)
    t = np.concatenate([np.arange(n_rest) * 0.01, run.t + n_rest * 0.01])
    rest = {
        "SpoolCmd": np.zeros(n_rest),
        "PumpDispCmd": np.full(n_rest, 100.0),
        "EngineSpeed": np.zeros(n_rest),
        "OilTemp": np.full(n_rest, run["OilTemp"][0]),
        "PP": np.abs(rng.normal(0.0, 0.3, n_rest)),
        "PA": pa_rest_bar + rng.normal(0.0, 0.3, n_rest),
        "PB": pb_rest_bar + np.abs(rng.normal(0.0, 0.3, n_rest)),
        "QP": np.abs(rng.normal(0.0, 0.1, n_rest)),
    }
    cols = {k: np.concatenate([rest[k], run[k]]) for k in rest}
    return Recording(t, cols, "rest then run")


def test_rest_offset_is_found_at_key_off_and_kept_when_the_engine_starts(model, normal_run) -> None:
    rec = rest_then_run(normal_run, 1.0, pb_rest_bar=12.0)  # PB reads 12 bar with no pressure
    found, check, _ = findings_of(rec)
    assert found == {("PB", "rest_offset"): 30.0 - 0.01}  # 3000th sample of the rest
    assert check[-1] != 0  # latched: no later rest has shown PB near tank
    det = detect(model, rec, CFG.alarm, CFG.horizon, gating=CFG.gating)
    running = [e for e in det.events if e["op_state"] == "normal"]
    assert running and all(e["state"] == "sensor_fault" for e in running)
    assert {(e["sensor"], e["sensor_check"]) for e in running} == {("PB", "rest_offset")}
    assert det.summary["alarm"] is False
    # A sensor reading tank at rest: no finding; the check off (rest_settle_s 0): none either.
    assert findings_of(rest_then_run(normal_run, 0.5))[0] == {}
    assert findings_of(rec, PlausibilityConfig(rest=RestCheck(rest_settle_s=0.0)))[0] == {}


def test_a_boom_parked_in_the_air_is_not_a_sensor_fault(model, normal_run) -> None:
    """Engine off with the boom held up: the cap side keeps the load pressure, 6 kN on the
    63 mm bore = 6000 / (pi 0.0315^2) Pa = 19.2 bar, the rod side bleeds to tank."""
    load_bar = 6000.0 / (np.pi * 0.0315**2) / 1e5
    assert 19.0 < load_bar < 19.5
    rec = rest_then_run(normal_run, load_bar)
    assert findings_of(rec)[0] == {}
    det = detect(model, rec, CFG.alarm, CFG.horizon, gating=CFG.gating)
    assert det.summary["sensor_fault"] is False


def test_detect_and_ticks_give_the_same_sensor_events(model, normal_run) -> None:
    """Frozen QP then an offset PA: states, findings and all event keys agree per sample."""
    qp, pa = normal_run["QP"].copy(), normal_run["PA"].copy()
    qp[idx(normal_run, 30.0) : idx(normal_run, 40.0)] = 7.5
    pa[idx(normal_run, 60.0) :] += 30.0
    rec = edited(normal_run, QP=qp, PA=pa)
    gating = GatingConfig()
    det = detect(model, rec, CFG.alarm, CFG.horizon, gating=gating)
    _, events = tick_recording(Ticker(model, CFG.alarm, CFG.horizon, gating=gating), rec)
    strip = lambda evs: [{k: v for k, v in e.items() if k != "J"} for e in evs]  # noqa: E731
    assert strip(events) == strip(det.events)
    named = {(e["sensor"], e["sensor_check"]) for e in det.events if e["sensor"]}
    assert named == {("QP", "frozen"), ("PA", "pump_below_port")}
    assert {e["state"] for e in det.events if e["sensor"]} == {"sensor_fault"}
    checks = {(c["sensor"], c["check"]) for c in det.summary["sensor_checks"]}
    assert checks == named
    assert det.summary["alarm"] is False  # a sensor fault is never a hydraulic alarm


@pytest.mark.parametrize(
    "cfg",
    [
        PlausibilityConfig(),
        PlausibilityConfig(
            frozen=FrozenCheck(frozen_s=0.3),
            stuck=StuckCheck(stuck_s=2.0),
            relation=RelationCheck(relation_s=0.2),
            rest=RestCheck(rest_settle_s=1.0, rest_max_bar=2.0),
            signal_range=RangeCheck(range_s=0.05),
        ),
        PlausibilityConfig(pump=PumpSystem("load_sensing", 20.0)),
    ],
    ids=["defaults", "short-times", "load-sensing"],
)
def test_kernel_equals_the_plain_python_twin(normal_run, cfg) -> None:
    """The numba kernel against tests/naive.py's sample-by-sample reading of the rules, on
    a run carrying every defect: a frozen QP, QP pinned at 0 L/min while oil flows, a stuck
    PB, PA reading high, PP out of range, and an engine-off rest with an offset PB, plus NaN
    gaps."""
    rec = normal_run
    n = len(rec)
    cols = {c: rec[c].copy() for c in COLUMNS}
    cols["QP"][idx(rec, 10.0) : idx(rec, 14.0)] = 12.34  # frozen
    cols["QP"][idx(rec, 36.5) : idx(rec, 40.5)] = 0.0  # pinned at zero while oil flows
    k0, k1 = idx(rec, 20.0), idx(rec, 35.0)
    cols["PB"][k0:k1] = 40.0 + np.random.default_rng(1).normal(0, 0.3, k1 - k0)  # stuck
    cols["PA"][idx(rec, 40.0) : idx(rec, 50.0)] += 60.0  # reads high: above the pump
    cols["PP"][idx(rec, 52.0) : idx(rec, 53.0)] = 450.0  # beyond the range
    r0, r1 = idx(rec, 60.0), idx(rec, 75.0)
    cols["EngineSpeed"][r0:r1] = 0.0  # key off, pressures settle to tank except PA
    cols["SpoolCmd"][r0:r1] = 0.0
    for s in ("PP", "PA"):
        cols[s][r0:r1] = np.random.default_rng(2).normal(0.5, 0.2, r1 - r0)
    cols["PB"][r0:r1] = 9.0
    for s, (a, b) in {"PA": (80.0, 80.5), "QP": (85.0, 85.2), "EngineSpeed": (86.0, 86.1)}.items():
        cols[s][idx(rec, a) : idx(rec, b)] = np.nan
    x = np.column_stack([cols[c] for c in COLUMNS])
    check, sig = Plausibility(cfg, CFG.alarm.min_engine_rpm).series(x)
    ref_check, ref_sig = naive.plausibility_findings(x, cfg, CFG.alarm.min_engine_rpm)
    np.testing.assert_array_equal(check, ref_check)
    np.testing.assert_array_equal(np.where(check > 0, sig, -1), ref_sig)
    assert n == len(check)
    if cfg.frozen.frozen_s < 1:  # the short times make every check fire: the comparison covers all
        assert set(np.unique(ref_check).tolist()) == {0, 1, 2, 3, 4, 5}
