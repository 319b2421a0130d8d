"""The end-stop estimate H leaves holds out by (monitor.model.endstop): the kernel against its
definition (tests/naive.py), worked by hand, live against batch, the swept volumes against
the cylinder's geometry, and its place in the model file."""

from __future__ import annotations

import math

import numpy as np
import pytest
from model_support import craft_model, set_key
from naive import near_stop

from monitor.errors import ConfigError, InputFileError, ModelFileError
from monitor.model.endstop import (
    StopTracker,
    StrokeModel,
    fit_stroke,
    near_stop_series,
    stroke_equations,
)
from monitor.model.hold import counted_holds
from monitor.model.modelfile import load_model

# 1 L each way and 60 L/min: 0.01 L, 1 % of the stroke, per 10 ms sample.
# Margins are chosen off the sample grid, so no answer hangs on rounding.
UNIT = StrokeModel(1.0, 1.0, margin=0.045, q_stall_lpm=1.0, n_stall=3)


def _flags(spool, qp, stroke: StrokeModel = UNIT) -> list[int]:
    return [
        int(v) for v in near_stop_series(np.asarray(spool, float), np.asarray(qp, float), stroke)
    ]


def test_worked_by_hand() -> None:
    """Unknown at the start; a stall puts the rod on the stop; travel moves it off, a hold
    keeps it, travel the other way brings it back; a gap makes it unknown again."""
    spool = [0.0] + [-60.0] * 3 + [0.0] + [60.0] * 5 + [0.0] * 2 + [-60.0] * 2 + [np.nan, 0.0]
    qp = [0.0] + [0.0] * 3 + [0.0] + [60.0] * 5 + [0.0] * 2 + [60.0] * 2 + [0.0, 0.0]
    # sample 0: hold, rod anywhere in 0..1: possibly on a stop.
    # 1-3: lowering with no flow: the stall counts at its third sample (n_stall 3): the
    #      interval is 0..1 until then, then 0.
    # 5-9: raising 1 % a sample: 0.01 .. 0.05; off the stop (margin 0.045) at the fifth.
    # 10-11: hold at 0.05: off.  12-13: lowering: 0.04, 0.03: on.
    # 14: a NaN command: anywhere.  15: hold, still anywhere.
    want = [1, 1, 1, 1, 1, 1, 1, 1, 1, 0, 0, 0, 1, 1, 1, 1]
    assert _flags(spool, qp) == want
    assert list(near_stop(spool, qp, 1.0, 1.0, 0.045, 1.0, 3)) == want


def test_a_long_travel_one_way_anchors_the_rod_without_a_stall() -> None:
    """From unknown, 1.2 strokes of lifting put the rod at the top whatever its start (the
    interval is cut at 1), so a hold after it is on the stop, and one after lowering half a
    stroke is not; the down volume (2 L) halves the travel per litre."""
    stroke = StrokeModel(1.0, 2.0, margin=0.052, q_stall_lpm=1.0, n_stall=3)
    spool = [60.0] * 120 + [0.0] * 3 + [-60.0] * 100 + [0.0] * 3
    got = _flags(spool, [60.0] * 120 + [0.0] * 3 + [60.0] * 100 + [0.0] * 3, stroke)
    assert got[:120] == [1] * 120  # unknown, then at the top
    assert got[120:123] == [1, 1, 1]  # hold on the top stop
    # 100 samples of 0.01 L at 2 L per stroke: 0.005 stroke each, 0.5 in all; within the
    # margin while 1 - 0.005 k > 0.948, k = 1..10.
    assert got[123:133] == [1] * 10 and got[133:223] == [0] * 90
    assert got[223:] == [0, 0, 0]


@pytest.mark.parametrize("seed", [1, 2, 3, 4, 5])
def test_kernel_and_live_tracker_match_the_definition(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = 4000
    levels = np.array([-80.0, -30.0, -6.0, -5.0, 0.0, 0.0, 4.0, 5.0, 6.0, 40.0, 90.0, np.nan])
    runs = rng.integers(1, 60, n)
    spool = np.repeat(rng.choice(levels, n), runs)[:n]
    # A flow per run of the command: a tenth of the runs stall (0.5 L/min), a few are cut
    # short (a run shorter than the stall count), one sample in a thousand is missing.
    stall = np.repeat(rng.random(n) < 0.1, runs)[:n]
    qp = np.where(stall, 0.5, np.abs(spool) * np.repeat(rng.uniform(0.1, 0.6, n), runs)[:n])
    qp[rng.random(n) < 0.001] = np.nan
    # Small volumes: a run of the lever travels much of the stroke, so the interval is cut
    # at the ends often.
    stroke = StrokeModel(rng.uniform(0.12, 0.5), rng.uniform(0.12, 0.5), 0.04, 1.0, 7)
    want = near_stop(spool, qp, stroke.volume_up_l, stroke.volume_down_l, 0.04, 1.0, 7)
    got = near_stop_series(spool, qp, stroke)
    assert 0.05 < want.mean() < 0.95  # both answers occur, each often
    np.testing.assert_array_equal(got, want)
    live = StopTracker(stroke)
    pushed = [live.push(float(s), float(q)) for s, q in zip(spool, qp, strict=True)]
    np.testing.assert_array_equal(pushed, want)


def test_counted_holds_leave_the_stop_out() -> None:
    spool = np.array([-60.0] * 3 + [0.0] * 4 + [60.0] * 10 + [0.0] * 4)
    qp = np.array([0.0] * 3 + [0.0] * 4 + [60.0] * 10 + [0.0] * 4)
    got = counted_holds(spool, qp, UNIT)
    assert list(got) == [0] * 3 + [0] * 4 + [0] * 10 + [1] * 4  # the mid-stroke hold only
    assert list(counted_holds(spool, qp, None)) == [0] * 3 + [1] * 4 + [0] * 10 + [1] * 4


def _rod_runs(volume_up_l: float, volume_down_l: float, seed: int, n_moves: int = 60):
    """Commands and the flow a rod of those volumes takes: a move's flow stops when the rod
    reaches its end (a stall), as a real cylinder's does."""
    rng = np.random.default_rng(seed)
    x, spool, qp = rng.uniform(0.2, 0.8), [], []
    for _ in range(n_moves):
        cmd = rng.choice([-1.0, 1.0]) * rng.uniform(20.0, 100.0)
        q = abs(cmd) * 0.25
        for _ in range(int(rng.integers(50, 600))):
            vol = volume_up_l if cmd > 0 else volume_down_l
            step = q * 0.01 / 60.0 / vol
            at_end = (cmd > 0 and x >= 1.0) or (cmd < 0 and x <= 0.0)
            spool.append(cmd)
            qp.append(0.0 if at_end else q)
            if not at_end:
                x = min(1.0, x + step) if cmd > 0 else max(0.0, x - step)
        hold = int(rng.integers(10, 200))
        spool += [0.0] * hold
        qp += [0.0] * hold
    return np.array(spool), np.array(qp)


def test_fit_finds_the_volumes_a_rod_was_driven_with() -> None:
    runs = [_rod_runs(1.56, 1.05, seed) for seed in (1, 2)]
    rows, rhs = stroke_equations(*runs[0])
    assert rows.shape == (len(rhs), 2) and set(np.unique(rhs)) <= {-1.0, 0.0, 1.0}
    fitted = fit_stroke([s for s, _ in runs], [q for _, q in runs])
    # Each stroke's travel is exact to within the last sample's step (0.25 % of a stroke).
    assert fitted.volume_up_l == pytest.approx(1.56, rel=0.01)
    assert fitted.volume_down_l == pytest.approx(1.05, rel=0.01)


def test_fit_on_the_simulated_boom_finds_its_cylinder() -> None:
    """The reference machine's swept volumes from its bore, rod and stroke (independent of
    the flows): the fit from pump flow sits within 3 % (the flow also compresses the oil)."""
    from monitor.sim.cycles import make_cycle
    from monitor.sim.machine import load_machine
    from monitor.sim.simulate import simulate

    m = load_machine()
    cap_l = math.pi / 4 * m.cylinder.bore_m**2 * m.cylinder.stroke_m * 1000.0
    ann_l = (
        math.pi / 4 * (m.cylinder.bore_m**2 - m.cylinder.rod_m**2) * m.cylinder.stroke_m * 1000.0
    )
    recs = [simulate(make_cycle("boom-cover", 300.0, seed), m, seed=seed) for seed in (3, 4)]
    fitted = fit_stroke([r["SpoolCmd"] for r in recs], [r["QP"] for r in recs])
    assert fitted.volume_up_l == pytest.approx(cap_l, rel=0.03)
    assert fitted.volume_down_l == pytest.approx(ann_l, rel=0.03)
    # And the estimate agrees with the simulator's RodPos about the holds on a stop.
    rec = simulate(make_cycle("boom", 300.0, 5), m, seed=5)
    spool, rod = rec["SpoolCmd"], rec["RodPos"] / (1000.0 * m.cylinder.stroke_m)
    near = near_stop_series(spool, rec["QP"], fitted).astype(bool)
    hold = np.abs(spool) <= 5.0
    on_stop = (rod < 0.01) | (rod > 0.99)
    assert (hold & on_stop).sum() > 100
    assert not np.any(hold & on_stop & ~near)  # no hold on a stop is counted


def test_too_few_strokes_is_a_clear_error() -> None:
    spool, qp = _rod_runs(1.0, 1.0, 3, n_moves=3)
    with pytest.raises(InputFileError, match=r"end stop to end stop \d+ times up and \d+ times"):
        fit_stroke([spool], [qp])
    # The estimate serves any cylinder loop (`monitor train --loop stick --hold on` said
    # "runs the boom"): the message names the rod, not the boom.
    with pytest.raises(InputFileError, match=r"runs the rod from end stop") as err:
        fit_stroke([spool], [qp])
    assert "boom" not in str(err.value)


def test_stroke_model_checks_its_values() -> None:
    for bad in ((0.0, 1.0), (1.0, -1.0), (np.nan, 1.0)):
        with pytest.raises(ConfigError, match="stroke volumes"):
            StrokeModel(*bad)
    with pytest.raises(ConfigError, match="margin"):
        StrokeModel(1.0, 1.0, margin=0.5)
    s = StrokeModel(1.5, 1.0)
    assert StrokeModel.from_dict(s.to_dict()) == s


GOOD_HOLD = {
    "window_n": 6000,
    "min_count": 300,
    "settle_n": 200,
    "outputs": [1, 2],
    "scale": [0.3, 0.7],
    "h0": 2.0,
    "stroke": {
        "volume_up_l": 1.57,
        "volume_down_l": 1.07,
        "margin": 0.05,
        "q_stall_lpm": 1.0,
        "n_stall": 20,
    },
}


def test_a_model_file_keeps_the_stroke(tmp_path) -> None:
    m = load_model(craft_model(tmp_path, set_key("hold", GOOD_HOLD)))
    assert m.hold is not None and m.hold.stroke == StrokeModel(1.57, 1.07, 0.05, 1.0, 20)
    assert m.hold.to_dict() == GOOD_HOLD


@pytest.mark.parametrize(
    ("change", "key"),
    [
        ({"volume_up_l": 0.0}, "volume_up_l"),
        ({"volume_down_l": "1"}, "volume_down_l"),
        ({"margin": 0.6}, "margin"),
        ({"q_stall_lpm": -1.0}, "q_stall_lpm"),
        ({"n_stall": 0}, "n_stall"),
    ],
)
def test_a_malformed_stroke_names_its_key(tmp_path, change, key) -> None:
    bad = {**GOOD_HOLD, "stroke": {**GOOD_HOLD["stroke"], **change}}
    with pytest.raises(ModelFileError, match=f"hold.stroke.{key}") as exc:
        load_model(craft_model(tmp_path, set_key("hold", bad)))
    assert "\n" not in str(exc.value)


def test_live_hold_window_leaves_out_the_same_holds_as_the_series() -> None:
    """The ticker's H (its own tracker, fed every sample) equals the offline series over the
    counted holds, sample by sample, with the stops mattering (the answer differs without)."""
    from monitor.model.hold import HoldModel, HoldWindow, hold_series

    rng = np.random.default_rng(9)
    spool, qp = _rod_runs(0.3, 0.2, 9, n_moves=40)
    e = rng.normal(0.0, 1.0, (len(spool), 3))
    e[:, 1] += np.where(spool == 0.0, 0.3, 0.0)  # an offset in the holds
    e[rng.random(len(spool)) < 0.002, 2] = np.nan
    stroke = StrokeModel(0.3, 0.2, margin=0.05, q_stall_lpm=1.0, n_stall=5)
    hold = HoldModel(500, 20, 10, (1, 2), np.array([1.0, 2.0]), 2.0, stroke)
    series = hold_series(e, counted_holds(spool, qp, stroke), hold)
    live = HoldWindow(hold)
    pushed = np.array([live.push(e[i], float(spool[i]), float(qp[i])) for i in range(len(e))])
    np.testing.assert_array_equal(np.isnan(pushed), np.isnan(series))
    ok = np.isfinite(series)
    assert ok.sum() > 500
    np.testing.assert_allclose(pushed[ok], series[ok], rtol=1e-12)
    every = hold_series(e, counted_holds(spool, qp, None), hold)
    assert not np.allclose(every[ok], series[ok])
