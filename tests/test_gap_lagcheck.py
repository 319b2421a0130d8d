"""A ``sensor_lag`` verdict checked against the engine's speed ripple (``lagcheck.py``):
hand-built signals with a known response and delay, then `monitor gap`'s diagnosis on short
simulated recordings without RodPos (a slow spool, a lagged sensor)."""

from __future__ import annotations

import numpy as np
import pytest

from monitor.gap.data.prepare import Prepared
from monitor.gap.data.segments import Segment
from monitor.gap.diagnose import diagnose
from monitor.gap.fit.calibrate import apply
from monitor.gap.judge import lagcheck
from monitor.gap.report.summary import summary_text
from monitor.io.recording import Recording
from monitor.sim.cycles import make_cycle
from monitor.sim.effects import Effect
from monitor.sim.machine import load_machine
from monitor.sim.simulate import simulate

M = load_machine()
N = 20_000
#: QP's response to the engine speed by construction (L/min per rpm) ...
GAIN = 0.004
#: ... and PP's (bar per rpm).
GAIN_PP = 0.02


def _delayed(x: np.ndarray, k: int) -> np.ndarray:
    return np.concatenate([np.full(k, x[0]), x[:-k]]) if k else x.copy()


T = np.arange(N) * 0.01
LEVER = np.sin(2 * np.pi * T / 7.0)


def _engine(ripple_rpm: float) -> np.ndarray:
    """2200 rpm with a white ripple of ``ripple_rpm`` (rms)."""
    return 2200.0 + np.random.default_rng(1).normal(0.0, ripple_rpm, N)


def _truth(delay: int, ripple_rpm: float = 5.0) -> dict[str, np.ndarray]:
    """Pump flow and pressure: a slow lever-driven wave plus the engine speed's ripple times
    a gain, read ``delay`` samples late without noise (what a simulation gives)."""
    ripple = _engine(ripple_rpm) - 2200.0
    return {
        "QP": _delayed(25.0 + 15.0 * LEVER + GAIN * ripple, delay),
        "PP": _delayed(150.0 + 40.0 * LEVER + GAIN_PP * ripple, delay),
    }


def _prepared(measured_delay: int, ripple_rpm: float = 5.0) -> Prepared:
    """The recording: ``_truth`` read ``measured_delay`` samples late, with the reference
    sensors' noise (0.1 L/min, 0.3 bar)."""
    rng = np.random.default_rng(2)
    truth = _truth(measured_delay, ripple_rpm)
    meas = {
        "QP": truth["QP"] + rng.normal(0.0, 0.1, N),
        "PP": truth["PP"] + rng.normal(0.0, 0.3, N),
    }
    cmd = {"EngineSpeed": _engine(ripple_rpm), "SpoolCmd": 50 * LEVER}
    return Prepared(T, cmd, meas, np.ones(N, bool), np.zeros(N), False, {}, {}, "hand", 500.0)


SEGMENTS = [Segment(0, N // 2 - 1, True), Segment(N // 2, N - 1, True)]


@pytest.mark.parametrize(
    ("delay", "expected"),
    # Change of the speed x(t) = e(t) - e(t-1), e white with variance v: var x = 2v.  A
    # prompt reading changes by GAIN x(t): slope GAIN.  One sample late it changes by
    # GAIN x(t-1), and cov(x(t), x(t-1)) = -v: slope -GAIN/2.  Two or more samples late
    # the changes share no ripple sample: slope 0.
    [(0, GAIN), (1, -GAIN / 2), (2, 0.0), (5, 0.0)],
)
def test_the_lag_zero_response_is_the_gain_a_prompt_reading_and_none_a_late_one(delay, expected):
    truth = _truth(delay)
    r = lagcheck.response(_prepared(0), SEGMENTS, "QP", truth, truth)
    # The noise-free series: the slope is exact up to the sample's own ripple statistics.
    assert r.undelayed == pytest.approx(expected, abs=0.03 * GAIN)
    assert r.pairs == N - 2 * 5 - 2  # the settle rows and each segment's first change


def test_prompt_readings_withdraw_the_sensor_lag_and_late_ones_keep_it():
    undelayed, lagged = _truth(0), _truth(3)
    prompt = lagcheck.check(_prepared(0), SEGMENTS, undelayed, lagged)
    assert prompt.prompt and not prompt.late and not prompt.sensor_named
    assert prompt.position == pytest.approx(1.0, abs=0.15)
    assert prompt.z >= lagcheck.Z_PROMPT
    late = lagcheck.check(_prepared(3), SEGMENTS, undelayed, lagged)
    assert late.late and not late.prompt and late.sensor_named
    assert late.position == pytest.approx(0.0, abs=0.15)
    # The standard error: QP noise 0.1 L/min, differenced (variance 2 x 0.01) over a ripple
    # change of variance 2 x 25 rpm^2 on about N pairs: sqrt(0.02 / (50 N)) per rpm.
    qp = next(r for r in late.responses if r.signal == "QP")
    assert qp.se == pytest.approx(np.sqrt(0.02 / (50 * N)), rel=0.3)
    d = late.as_dict()
    assert d["readings"] == "late" and {r["signal"] for r in d["signals"]} == {"QP", "PP"}


def test_no_ripple_no_verdict_change():
    """A constant engine speed (as the simulator's own duty cycles have) cannot tell a late
    reading from a prompt one: the check abstains and the sensor lag stands."""
    chk = lagcheck.check(_prepared(0, ripple_rpm=0.0), SEGMENTS, _truth(0, 0.0), _truth(3, 0.0))
    assert not chk.decided and chk.sensor_named and not chk.late
    assert chk.as_dict()["prompt_z"] is None and chk.as_dict()["readings"] == "undecided"


def _without_rodpos(effects: list[Effect], seed: int, ripple_rpm: float) -> Recording:
    """60 s of boom cycles on a machine a few percent off nominal, the engine speed with a
    white ripple (as diesel engines under a governor show, sample to sample), no RodPos."""
    cmd = make_cycle("boom", 60.0, seed)
    cols = dict(cmd.columns)
    rng = np.random.default_rng(seed + 1000)
    cols["EngineSpeed"] = cols["EngineSpeed"] + rng.normal(0.0, ripple_rpm, len(cmd))
    machine = apply(M, {"mass": 1.04, "gravity_load": 0.97, "volumes": 1.03})
    rec = simulate(Recording(cmd.t, cols, cmd.source), machine, effects=effects, seed=seed)
    drop = ("RodPos", "RodPosTrue", "RodVel", "SpoolPos")
    return Recording(rec.t, {n: v for n, v in rec.columns.items() if n not in drop}, "sim")


#: A reduced candidate list keeps the diagnoses short; the full list runs in the benchmark.
CANDIDATES = ("sensor_lag", "spool_dynamics")


@pytest.fixture(scope="module")
def slow_spool_recording():
    return _without_rodpos([Effect.make("spool_dynamics", natural_freq_hz=5.0)], 31, 10.0)


def test_a_slow_spool_without_rodpos_is_named(slow_spool_recording):
    d = diagnose(slow_spool_recording, M, effects=CANDIDATES)
    assert not d.parts.prep.has_rodpos
    assert d.finding.verdict == "spool_dynamics"
    # Named outright (the simulator's own spool fits best) or after the check withdrew a
    # sensor lag that fitted as well.
    assert d.finding.lag_check is None or d.finding.lag_check["sensor_named"] is False


@pytest.fixture(scope="module")
def lag_only(slow_spool_recording):
    """The slow spool diagnosed with the sensor lag as the only candidate: it explains the
    gap, and the check must withdraw it."""
    return diagnose(slow_spool_recording, M, effects=("sensor_lag",))


def test_a_sensor_lag_standing_in_for_a_slow_spool_is_withdrawn(lag_only):
    d = lag_only
    assert d.ranking.singles[0].heldout_reduction >= 0.5  # it would have been named
    assert d.finding.verdict != "sensor_lag"
    assert d.finding.lag_check is not None and d.finding.lag_check["sensor_named"] is False
    assert d.finding.lag_check["readings"] == "prompt"
    assert d.finding.lag_check["verdict_without_check"] == "sensor_lag"
    qp = next(r for r in d.finding.lag_check["signals"] if r["signal"] == "QP")
    assert qp["position"] > 0.5


def test_the_report_says_why_the_sensor_lag_was_not_named(lag_only):
    from monitor.gap.report.document import build_report

    rep = build_report(lag_only, M)
    assert rep["verdict"] != "sensor_lag" and rep["lag_check"]["sensor_named"] is False
    assert "Not a sensor lag: QP and PP follow the engine's speed ripple promptly" in (
        summary_text(rep)
    )


def test_a_lagged_sensor_without_rodpos_keeps_its_verdict():
    rec = _without_rodpos([Effect.make("sensor_lag", delay_ms=30.0)], 32, 10.0)
    d = diagnose(rec, M, effects=CANDIDATES)
    assert d.finding.verdict == "sensor_lag"
    assert d.finding.lag_check is not None and d.finding.lag_check["sensor_named"] is True
    assert d.finding.lag_check["readings"] == "late"


def test_readings_late_by_the_delay_they_share_are_the_recordings_timing():
    """Every reading 15 ms late (a pure delay of all four, as a recording's acquisition
    makes it), no rod to compare with: a delay of 1.5 samples moves
    the engine ripple's lag-zero response as the fitted lag does, so the ripple reads
    ``late`` against the undelayed simulator; against the simulator re-timed by each
    reading's fitted delay it shows nothing more, and the delay every reading shares
    (5-25 ms: the recording's timing) decides: the lag must clearly beat the re-timing.
    On main the ripple alone kept ``sensor_lag``."""
    rec = _without_rodpos([Effect.make("sensor_lag", delay_ms=15.0)], 33, 10.0)
    d = diagnose(rec, M, effects=CANDIDATES)
    t = d.finding.timing
    assert d.finding.lag_check is not None and d.finding.lag_check["readings"] == "late"
    assert t is not None and 5.0 <= t["shared_ms"] <= 25.0 and not t["late_signals"]
    # The re-timed readings answer the ripple as the recording does: not late beyond them.
    assert t["ripple"]["against"] == "re-timed" and t["ripple"]["readings"] != "late"
    assert all(0.0 < ms <= 25.0 for ms in t["ripple"]["delays_ms"].values())
    # Re-timed, the readings leave no structured gap the lag removes at a practical level.
    assert t["retimed"]["effect_removes_practical"] is False
    assert d.finding.verdict == "none"
