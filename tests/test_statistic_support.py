"""What a statistic's threshold rests on (monitor.model.support) and `monitor train`'s rule
that switches off a statistic its held-out data does not support (monitor.training.support):
counted in independent windows, the false-alarm rate with its Poisson bound, and a threshold
set on one half of the held-out data (cooler oil) judged on the other (warmer oil)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

from monitor.io.recording import Recording
from monitor.model.statistic import HeldOut, Statistic
from monitor.model.support import implied_rate, independent_windows, rate_upper95, window_maxima
from monitor.model.threshold import ThresholdRule
from monitor.training.support import earned, halves, rests_on_one_event


def test_poisson_bound_by_hand() -> None:
    """0 events in 1 h: -ln(0.05) = 2.996 per hour; 2 events in 2 h: chi2(0.95, 6) / 2 / 2
    = 12.592 / 4 (the Garwood table's 6.296 for 2 events, per 2 h)."""
    assert rate_upper95(0, 1.0) == pytest.approx(2.9957, abs=1e-4)
    assert rate_upper95(2, 2.0) == pytest.approx(12.5916 / 4, abs=1e-3)
    assert rate_upper95(0, 0.0) == float("inf")


def test_window_maxima_need_half_a_window_judged() -> None:
    x = np.array([1, 2, 3, np.nan, np.nan, np.nan, 5, np.nan, 0, 9.0])
    m = window_maxima(x, 3)  # the last, partial window is left out
    assert np.isnan(m[1]) and list(m[[0, 2]]) == [3.0, 5.0] and len(m) == 3


def test_correlated_windows_count_less() -> None:
    """Maxima of an AR(1) chain with rho 0.8 count as n (1 - 0.8) / (1 + 0.8); independent
    ones as n."""
    rng = np.random.default_rng(3)
    n = 40_000
    white = rng.standard_normal(n)
    ar = np.empty(n)
    ar[0] = white[0]
    for i in range(1, n):
        ar[i] = 0.8 * ar[i - 1] + white[i]
    _, rho, n_eff = independent_windows([ar])
    assert rho == pytest.approx(0.8, abs=0.02)
    assert n_eff == pytest.approx(n * 0.2 / 1.8, rel=0.1)
    count, rho0, n_eff0 = independent_windows([white[:20_000], white[20_000:]])
    assert count == n and rho0 < 0.02 and n_eff0 == pytest.approx(n, rel=0.04)


def test_implied_rate_counts_windows_above() -> None:
    """120 independent 30 s windows (1 h), 2 of them above: 2 per hour, bound 6.30 / h."""
    rng = np.random.default_rng(4)
    maxima = rng.uniform(0.0, 1.0, 120)
    maxima[[10, 70]] = 5.0
    r = implied_rate([maxima], 2.0, 30.0)
    assert r["windows_above"] == 2
    hours = r["independent_windows"] * 30 / 3600
    assert r["false_alarms_per_h"] == pytest.approx(2 / hours, rel=1e-2)
    assert r["false_alarms_per_h_upper95"] == pytest.approx(6.2958 / hours, rel=1e-2)


@dataclass(frozen=True)
class MeanModel:
    window_n: int
    m0: float = float("nan")

    def to_dict(self) -> dict[str, Any]:
        return {"window_n": self.window_n, "m0": self.m0}


class Mean(Statistic):
    """|mean of the first output's residual| over non-overlapping-in-spirit 5 s windows
    (a plain moving mean, NaN until the window is full)."""

    name = "Q"
    key = "mean_q"
    threshold_key = "m0"
    title = "mean statistic Q"

    def unscaled(self, held: HeldOut) -> MeanModel:
        return MeanModel(500)

    def series(self, e: np.ndarray, rec: Recording) -> np.ndarray:
        c = np.concatenate(([0.0], np.cumsum(e[:, 0])))
        out = np.full(len(e), np.nan)
        out[499:] = np.abs(c[500:] - c[:-500]) / 500
        return out

    def window(self, columns: Sequence[str], n_out: int) -> Any:
        raise NotImplementedError  # not judged live in these tests

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> MeanModel:
        return MeanModel(int(d["window_n"]), float(d["m0"]))


def _held(minutes: float, warm_offset: float, seed: int = 5) -> HeldOut:
    """Two held-out parts of ``minutes`` each: white residuals (z), oil 25 -> 35 degC in the
    first and 35 -> 45 degC in the second, whose residual is moved by ``warm_offset``."""
    n = int(minutes * 6000)
    rng = np.random.default_rng(seed)
    es, recs = [], []
    for k, (lo, hi) in enumerate(((25.0, 35.0), (35.0, 45.0))):
        e = rng.standard_normal((n, 1)) + (warm_offset if k else 0.0)
        oil = np.linspace(lo, hi, n)
        es.append(e)
        recs.append(Recording(np.arange(n) * 0.01, {"OilTemp": oil, "SpoolCmd": np.zeros(n)}))
    return HeldOut(es, recs, ("PP",))


def test_halves_deal_sessions_alternately_and_cut_one_recording() -> None:
    """Two sessions: one each (by oil temperature); one recording: its cooler and warmer
    half."""
    two = _held(1.0, 0.0)
    cool, warm = halves(two)
    assert [r["OilTemp"][0] for r in cool.recordings] == [25.0]
    assert [r["OilTemp"][0] for r in warm.recordings] == [35.0]
    one = HeldOut([two.residuals[0]], [two.recordings[0]], ("PP",))
    first, second = halves(one)
    assert first.recordings[0]["OilTemp"].max() < second.recordings[0]["OilTemp"].min()
    assert len(first.residuals[0]) == len(second.residuals[0]) == 3000


def test_a_statistic_that_holds_across_the_halves_stays_on() -> None:
    """White residuals: a 5 s mean has sd 1/sqrt(500) = 0.045 in both halves, the max rule
    (2 x the largest) holds from one half to the other."""
    held = _held(5.0, 0.0)
    stat = Mean().fit(held, ThresholdRule())
    # 118 windows of 5 s (a part's first is not full); neighbours share the moving mean's
    # start, so fewer count as independent
    assert 40 <= stat.support_["independent_windows"] < 118 == stat.support_["windows"]
    assert stat.support_["windows_above"] == 0
    assert stat.support_["spool_share"] == {"hold": 1.0, "raise": 0.0, "lower": 0.0}
    assert earned(stat, held, ThresholdRule()) is None
    assert 0 < stat.support_["transfer"]["ratio"] < 1


def test_a_threshold_the_warmer_half_exceeds_is_off() -> None:
    """The warmer half's residual moved by 0.5 z: fitted on the cooler half (largest 5 s
    mean about 3.5 sd = 0.16, threshold 0.32), the warmer half's means sit at 0.5 (about
    1.6 x): off, naming both oil ranges."""
    held = _held(5.0, 0.5)
    stat = Mean().fit(held, ThresholdRule())
    why = earned(stat, held, ThresholdRule())
    assert why is not None and "oil 25-35 degC" in why and "oil 35-45 degC" in why
    assert 1.2 < stat.support_["transfer"]["ratio"] < 2.5


def test_too_few_independent_windows_is_off() -> None:
    """2 x 15 s of held-out data: 6 windows of 5 s, fewer than the 8 a threshold needs; the
    line says how much more data would do."""
    held = _held(0.25, 0.0)
    stat = Mean().fit(held, ThresholdRule())
    why = earned(stat, held, ThresholdRule())
    assert why is not None and "independent 5 s windows" in why and "more held-out" in why


def test_one_recording_cannot_show_a_threshold_holds_between_sessions() -> None:
    """Ten minutes of one recording: enough windows, halves that agree, but one session."""
    two = _held(5.0, 0.0)
    e = np.concatenate(two.residuals)
    rec = Recording(
        np.arange(len(e)) * 0.01,
        {k: np.concatenate([r[k] for r in two.recordings]) for k in ("OilTemp", "SpoolCmd")},
    )
    held = HeldOut([e], [rec], ("PP",))
    stat = Mean().fit(held, ThresholdRule())
    why = earned(stat, held, ThresholdRule())
    assert why is not None and why.startswith("its threshold rests on one recording")
    assert "at least 2 sessions (--held-out)" in why


def _spiked(spikes: Sequence[tuple[int, float]]) -> HeldOut:
    """Five minutes in each of two parts, white residuals, plus a 5 s step of 20 z in
    ``(part, minute)`` for each spike."""
    held = _held(5.0, 0.0)
    for part, minute in spikes:
        a = int(minute * 6000)
        held.residuals[part][a : a + 500, 0] += 20.0
    return held


def test_a_threshold_set_by_one_spike_is_called_thin() -> None:
    """One 5 s step of 20 z at 3.0 min of the first part: its window's mean reaches about
    20, every other window's stays near 3.5 sd of a 5 s mean (0.16), about 100 x less; the
    max rule puts the threshold at 2 x 20. One line names the statistic's event, its time
    and ratio and what data would switch the statistic on."""
    held = _spiked([(0, 3.0)])
    stat = Mean().fit(held, ThresholdRule())
    assert stat.threshold_ == pytest.approx(40.0, rel=0.05)
    why = rests_on_one_event(stat, held)
    assert why is not None and why.startswith("its threshold rests on one event")
    assert " at 3.0 min " in why and "would switch it on" in why
    event = stat.support_["one_event"]
    assert 60 < event["ratio"] < 200
    assert 179.0 <= event["t_s"] <= 181.0  # the window holding the step's end


def test_two_like_events_are_not_one() -> None:
    """The same step in both parts: the threshold rests on two events, neither thin."""
    held = _spiked([(0, 3.0), (1, 2.0)])
    stat = Mean().fit(held, ThresholdRule())
    assert rests_on_one_event(stat, held) is None and "one_event" not in stat.support_


def test_an_optional_statistic_on_one_event_is_off_and_says_why(monkeypatch) -> None:
    """`monitor train`'s rule: an optional statistic whose threshold rests on one event is
    off, with the line; the model keeps no threshold for it."""
    from monitor.training import statistics as stats

    held = _spiked([(0, 3.0)])
    monkeypatch.setattr(stats, "registry", lambda: [Mean])
    monkeypatch.setattr(stats, "earned", lambda *a: None)  # the other checks pass

    class Settings:
        class thresholds:  # noqa: N801
            rule = ThresholdRule()

        class statistics:  # noqa: N801
            support_check = True

    class Model:
        statistics: dict[str, Any] = {}  # noqa: RUF012

    said: list[str] = []
    notes, support = stats.fit_statistics(Model(), held, Settings(), said.append)
    assert notes["mean_q"].startswith("off: its threshold rests on one event")
    assert any(s.startswith("  mean statistic Q off: its threshold rests on one") for s in said)
    assert support["Q"]["one_event"]["ratio"] > 60
