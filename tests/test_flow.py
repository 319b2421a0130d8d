"""The flow-continuity statistic F (monitor.model.flow, issue 38): the pump's flow beyond what
the rod's lowering speed takes, tested against the twin in tests/naive.py written from the
definition alone, and against recordings whose flow is known by construction."""

from __future__ import annotations

import numpy as np
import pytest
from naive import flow_statistic

from monitor.detection.alarm import AlarmConfig, AlarmMachine, State
from monitor.errors import InputFileError
from monitor.io.recording import Recording
from monitor.model.flow import Flow, FlowModel, FlowWindow, flow_series
from monitor.model.flow_oil import OilTrend
from monitor.model.statistic import HeldOut, Statistic, naming_series
from monitor.model.threshold import ThresholdRule
from monitor.training.statistics import own_data
from monitor.training.support import support_line


def _lowering(
    n: int,
    speed_mm_s: float,
    qp_lpm: np.ndarray | float,
    start_mm: float = 480.0,
    spool_pct: float = -50.0,
) -> dict[str, np.ndarray]:
    """A boom lowering at a constant speed from ``start_mm`` with a given pump flow."""
    t = np.arange(n) * 0.01
    return {
        "SpoolCmd": np.full(n, spool_pct),
        "RodPos": start_mm - speed_mm_s * t,
        "QP": np.broadcast_to(np.asarray(qp_lpm, dtype=float), (n,)).copy(),
        "EngineSpeed": np.full(n, 2000.0),
    }


def _rec(cols: dict[str, np.ndarray]) -> Recording:
    n = len(cols["SpoolCmd"])
    return Recording(np.arange(n) * 0.01, dict(cols))


def _messy(seed: int, n: int = 3000) -> tuple[np.ndarray, ...]:
    """Lowerings and raisings at varied speeds, bounces, stops, NaN samples and gated rows."""
    rng = np.random.default_rng(seed)
    speed = np.repeat(rng.choice([-150.0, -60.0, -9.0, 0.0, 80.0], n), rng.integers(5, 60, n))[:n]
    speed += rng.normal(0.0, 4.0, n)  # some steps change the speed by more than 15 mm/s
    rod = np.clip(250.0 + np.cumsum(speed) * 0.01, 0.0, 500.0)
    spool = np.where(speed < -20.0, -60.0, np.where(speed > 20.0, 40.0, -25.0))
    spool[rng.random(n) < 0.02] = -15.0
    qp = 0.4 + 0.11 * np.abs(speed) + rng.normal(0.0, 0.3, n)
    for x in (spool, rod, qp):
        x[rng.random(n) < 0.005] = np.nan
    ok = rng.random(n) > 0.01
    return spool, rod, qp, ok


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_series_and_live_window_match_the_definition(seed: int) -> None:
    """Offline, live and the twin agree sample by sample, with the judged samples decided in
    the kernel: residuals with NaN rows (gated), and some of those gated for their oil alone,
    inside F's own oil range (40..55 degC, ends in) or beyond it."""
    spool, rod, qp, ok = _messy(seed)
    n = len(spool)
    rng = np.random.default_rng(100 + seed)
    e = rng.normal(0.0, 1.0, (n, 2))
    e[~ok, rng.integers(0, 2, int((~ok).sum()))] = np.nan
    gated = np.repeat(rng.random(n // 50) < 0.3, 50)[:n]  # whole stretches gated
    e[gated, 0] = np.nan
    warm = np.repeat(rng.choice([45.0, 55.0, 58.0, np.nan], n // 50), 50)[:n]
    beyond = np.where(gated, warm, np.nan)
    flow = FlowModel(40, 200, 0.3, 0.105, 0.0, 500.0, 0.7, oil_lo_c=40.0, oil_hi_c=55.0)
    rec = _rec({"SpoolCmd": spool, "RodPos": rod, "QP": qp})
    got = flow_series(rec, e, flow, beyond)
    want = flow_statistic(spool, rod, qp, e, 0.3, 0.105, 0.0, 500.0, 0.7, 40, beyond, (40.0, 55.0))
    assert np.array_equal(np.isnan(got), np.isnan(want))
    assert np.isfinite(want).sum() > 1000 and len(np.unique(want[np.isfinite(want)])) > 50
    np.testing.assert_allclose(got[np.isfinite(want)], want[np.isfinite(want)], rtol=1e-9)
    # The warm stretches inside F's range are judged, those beyond it are not.
    assert np.isfinite(got[gated & (warm <= 55.0)]).any()
    assert not np.isfinite(got[gated & ~(warm <= 55.0)]).any()
    window = FlowWindow(flow)
    live = [window.push(e[i], beyond[i], spool[i], rod[i], qp[i]) for i in range(n)]
    np.testing.assert_array_equal(np.asarray(live), got)
    # Without an oil range of its own (a model file from before it) F judges where J does.
    old = FlowModel(40, 200, 0.3, 0.105, 0.0, 500.0, 0.7)
    np.testing.assert_array_equal(flow_series(rec, e, old, beyond), flow_series(rec, e, old))


def test_a_known_leak_gives_its_mean_in_standard_errors() -> None:
    """QP = a + b |v| + 0.6 L/min: every counted sample's excess is the leak, so F is the
    leak over the scale.  Lowering at 20 mm/s from 480.05 mm, RodPos is below 475 mm (25 mm
    inside the stroke's 500) from sample 26 on, RodPos 0.1 s before from sample 36: the
    first counted sample (the speed's 21 samples of history are there from sample 20), and
    the window of 100 is full at sample 135."""
    a, b, leak, v = 0.4, 0.12, 0.6, 20.0
    cols = _lowering(600, v, a + b * v + leak, start_mm=480.05)
    flow = FlowModel(100, 500, a, b, 0.0, 500.0, 0.15)
    judged = np.zeros((600, 0))  # no residuals: every sample judged
    f = flow_series(_rec(cols), judged, flow)
    assert np.all(np.isnan(f[:135]))
    np.testing.assert_allclose(f[135:], leak / 0.15, rtol=1e-9)
    # A flow short of the line is no leak: F is 0, not negative.
    cols["QP"] = np.full(600, a + b * v - 0.6)
    assert np.nanmax(flow_series(_rec(cols), judged, flow)) == 0.0


def _commissioning(seed: int, leak: float = 0.0, oil_lpm_per_c: float = 0.0) -> Recording:
    """24 lowerings of 1.5 s at 60-180 mm/s from 480 mm, each raised back, QP = 0.5 + 0.1 |v|
    (+ ``leak`` while lowering) with a flow meter's noise of 0.2 L/min; the oil warms from 30
    to 45 degC over the run, and while lowering QP grows by ``oil_lpm_per_c`` per degC above
    37.5 (a leakage thinner oil raises)."""
    rng = np.random.default_rng(seed)
    parts = []
    for speed in rng.uniform(60.0, 180.0, 24):
        down = _lowering(150, speed, 0.5 + 0.1 * speed + leak, start_mm=480.0)
        up = _lowering(150, -speed, 0.5 + 0.1 * speed, start_mm=float(down["RodPos"][-1]))
        up["SpoolCmd"][:] = 50.0
        down["Lowering"], up["Lowering"] = np.ones(150), np.zeros(150)
        parts += [down, up]
    cols = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    lowering = cols.pop("Lowering") == 1.0
    cols["OilTemp"] = np.linspace(30.0, 45.0, len(cols["QP"]))
    cols["QP"] = cols["QP"] + rng.normal(0.0, 0.2, len(cols["QP"]))
    cols["QP"][lowering] += oil_lpm_per_c * (cols["OilTemp"][lowering] - 37.5)
    return _rec(cols)


def _fit(rec: Recording, count_n: int = 500) -> Flow:
    held = own_data(HeldOut([np.zeros((len(rec), 0))], [rec], ("PP", "QP"), [rec]))
    return Flow(count_n).fit(held, ThresholdRule())


def test_fit_learns_the_line_and_a_leak_stands_out() -> None:
    """Fitted on healthy lowerings the line is the one the flow was made from (to the meter's
    noise), the stroke is the span RodPos covered; the scale is the standard error of a
    window's mean, the noise over sqrt(count_n) (a counted sample's excess is the mean of
    ten readings, and neighbours share nine of them); F on a machine that leaks 0.5 L/min
    while lowering is that leak over the scale, far above the threshold, which is at least
    ``MIN_SCORE``; on another healthy recording F stays below it."""
    rec = _commissioning(1)
    stat = _fit(rec)
    p = stat.params_
    assert p.a_lpm == pytest.approx(0.5, abs=0.05)
    assert p.b_lpm_per_mm_s == pytest.approx(0.1, abs=0.001)
    assert p.lo_mm == pytest.approx(float(np.min(rec["RodPos"])))
    assert p.hi_mm == pytest.approx(480.0)
    assert p.scale == pytest.approx(0.2 / np.sqrt(500), rel=0.15)
    assert p.f0 >= 4.0
    assert stat.support_["lowering_s"] > 10.0 and "standard_error_lpm" in stat.support_
    healthy = _commissioning(2)
    assert np.nanmax(stat.series(np.zeros((len(healthy), 0)), healthy)) < p.f0
    worn = _commissioning(3, leak=0.5)
    f = stat.series(np.zeros((len(worn), 0)), worn)
    assert np.nanmax(f) == pytest.approx(0.5 / p.scale, rel=0.15)


def test_its_own_oil_range_from_commissioning_s_oil_trend() -> None:
    """The oil range F judges beyond the envelope: a trend by construction is found (one
    point per lowering), and the range ends where the trend, taken two standard errors
    steeper, has risen by a quarter of the threshold (f0 x scale, L/min), or one span (15
    degC) beyond the oil the lowerings saw; a falling trend cannot raise a false alarm of a
    one-sided F, so only the span ends it on that side.  The arithmetic of the rule by hand:
    mean 38, allowance 0.04 L/min, slope 0.002 +- 0.001 -> 0.04 / 0.004 = 10 degC warmer."""
    trend = OilTrend(30, 38.0, 30.0, 45.0, 0.002, 0.001)
    assert trend.range_c(0.04) == pytest.approx((15.0, 48.0))
    assert OilTrend(30, 38.0, 30.0, 45.0, -0.01, 0.001).range_c(0.04) == pytest.approx(
        (38.0 - 0.04 / 0.012, 60.0)
    )
    assert OilTrend(2, 38.0, 30.0, 45.0, np.nan, np.nan).range_c(0.04) == (30.0, 45.0)
    steep = _fit(_commissioning(1, oil_lpm_per_c=0.03))
    t = steep._oil
    assert t.lowerings == 24 and t.slope_lpm_per_c == pytest.approx(0.03, rel=0.2)
    p = steep.params_
    allowance = 0.25 * p.f0 * p.scale
    assert p.oil_hi_c == pytest.approx(
        t.mean_c + allowance / (t.slope_lpm_per_c + 2 * t.se_lpm_per_c)
    )
    assert t.hi_c < 45.0 < p.oil_hi_c + 5.0  # the envelope's own margin reaches further
    flat = _fit(_commissioning(1))
    assert flat.params_.oil_hi_c > steep.params_.oil_hi_c
    assert "own oil range" in flat.support_["oil_range"]
    assert "lowerings" in support_line(flat)


def test_off_with_its_reason_without_rodpos_or_lowering() -> None:
    rec = _commissioning(1)
    no_rod = Recording(rec.t, {k: v for k, v in rec.columns.items() if k != "RodPos"})
    with pytest.raises(InputFileError, match="no RodPos"):
        _fit(no_rod)
    with pytest.raises(InputFileError, match="s of steady lowering"):
        _fit(rec, count_n=5000)


def test_header_round_trip_and_checks() -> None:
    flow = FlowModel(2000, 30000, 0.4, 0.11, -1.0, 507.0, 0.05, 4.0)
    header = {"flow": flow.to_dict()}
    Flow.check_header(header)
    assert Flow.read(header, 4) == flow
    header["flow"]["count_n"] = 0
    with pytest.raises(ValueError, match="count_n"):
        Flow.check_header(header)


def test_an_alarm_f_raises_is_named_piston_wear() -> None:
    """The level's member names the fault: where F's ratio tops J's (strictly) the name
    is F's; where J is NaN the level is NaN and nothing names it."""
    j = np.array([0.5, 0.5, 2.0, np.nan, 0.5])
    f = np.array([np.nan, 3.0, 3.0, 3.0, 1.2])  # ratios: -, 1.5, 1.5, 1.5, 0.6
    named = naming_series([(j, 1.0), (f, 2.0)], ["", Flow.names])
    assert list(named) == ["", "piston_wear", "", "", "piston_wear"]
    assert issubclass(Flow, Statistic) and Flow.names == "piston_wear"
    machine = AlarmMachine(AlarmConfig(raise_samples=2), 1.0)
    states = [machine.step(1.5, True, 2000.0, named="piston_wear") for _ in range(3)]
    assert states[-1] is State.FAULT and machine.fault == "piston_wear"


def test_live_ticker_gives_the_offline_f_and_events_named_piston_wear(model) -> None:
    """The live ticker's F equals the offline series sample by sample; with F ruling the
    level (a line of zero flow: every lowering's whole QP is excess) both paths raise the
    same alarm and name it piston_wear.  The recording's last 15 s run 10 degC above the
    envelope's oil (its trained range plus the 5 degC margin): J is not judged there, F is
    (its own range reaches that oil) and sets the level alone, and the summary counts those
    seconds as judged beyond the oil; a warm recording F alone judged and found quiet is not
    judged (F looks for piston wear only); with F's range short of that oil nobody judges."""
    import dataclasses

    from live_support import assert_same_events, rows_of

    from monitor.config.settings import load_config
    from monitor.detection.offline import detect
    from monitor.detection.ticker import Ticker, event
    from monitor.io.recording import Recording
    from monitor.sim.cycles import make_cycle
    from monitor.sim.machine import load_machine
    from monitor.sim.simulate import simulate

    cfg = load_config()
    rec = simulate(make_cycle("boom", 40.0, 6), load_machine(), seed=6)
    warm_c = model.envelope.range_of("OilTemp")[1] + cfg.gating.validity.margin_c + 10.0
    oil = rec["OilTemp"].copy()
    oil[rec.t >= 25.0] = warm_c
    rec = Recording(rec.t, {**rec.columns, "OilTemp": oil}, rec.source, rec.meta)
    flow = FlowModel(200, 1000, 0.0, 0.0, -1e3, 1e3, 1.0, 4.0, 0.0, warm_c + 1.0)
    m = dataclasses.replace(model, statistics={**model.statistics, "flow": flow})
    det = detect(m, rec, cfg.alarm, cfg.horizon)
    assert det.summary["alarm"] and det.summary["fault"] == "piston_wear"
    ticker = Ticker(m, cfg.alarm, cfg.horizon)
    fs, levels, events = np.empty(len(rec)), np.empty(len(rec)), []
    for i, row in enumerate(rows_of(rec)):
        tick = ticker.tick(row)
        fs[i], levels[i] = ticker.value("F"), tick.level
        if tick.changed:
            events.append(event(tick, ticker.fault, ticker.eps0, rec.meta.get("start_time_s")))
    assert np.array_equal(np.isnan(fs), np.isnan(det.series["F"]))
    ok = np.isfinite(det.series["F"])
    assert ok.sum() > 500
    np.testing.assert_allclose(fs[ok], det.series["F"][ok], rtol=1e-9)
    np.testing.assert_array_equal(np.isnan(levels), np.isnan(det.level))
    assert_same_events(events, det)
    assert {e["fault"] for e in events if e["state"] == "fault"} == {"piston_wear"}
    assert not np.isfinite(det.series["J"][rec.t >= 25.0]).any()
    # The jump of the oil is believed after the gate's confirmation; from then on F alone.
    warm = (rec.t >= 25.0) & ok & np.isfinite(det.level)
    assert warm.sum() > 1000
    np.testing.assert_allclose(det.level[warm], det.series["F"][warm] / 4.0, rtol=1e-12)
    alone = np.isfinite(det.level) & ~np.isfinite(det.series["J"])
    running = np.isin(det.state, (State.NORMAL, State.FAULT))
    assert det.summary["judged_beyond_oil_s"] == pytest.approx((alone & running).sum() * 0.01)
    assert det.summary["judged_beyond_oil_s"] > 5.0
    # Warm throughout and F quiet (a threshold it never reaches): judged by F alone, for
    # piston wear only, so not judged, and the summary says how long F judged it.
    hot = Recording(rec.t, {**rec.columns, "OilTemp": np.full(len(rec), warm_c)})
    quiet = dataclasses.replace(flow, f0=1e9)
    m = dataclasses.replace(model, statistics={**model.statistics, "flow": quiet})
    s = detect(m, hot, cfg.alarm, cfg.horizon).summary
    assert (s["verdict"], s["judged_s"]) == ("not_judged", 0.0) and s["judged_beyond_oil_s"] > 15
    assert f"F alone judged {s['judged_beyond_oil_s']:.1f} s" in s["not_judged_why"]
    short = dataclasses.replace(flow, oil_hi_c=warm_c - 1.0)
    m = dataclasses.replace(model, statistics={**model.statistics, "flow": short})
    cold = detect(m, rec, cfg.alarm, cfg.horizon)
    assert not np.isfinite(cold.level[rec.t >= 25.0]).any()
    assert cold.summary["judged_beyond_oil_s"] == 0.0
