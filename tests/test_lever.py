"""The full-lever statistic L (monitor.model.lever, issue 17): PP's mean residual over the
samples of a window with the lever beyond 80 %, per direction, tested against the twin in
tests/naive.py written from the definition alone."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from model_support import craft_model, set_key
from naive import lever_statistic

from monitor.errors import ConfigError, InputFileError, ModelFileError
from monitor.model.bias import N_BIAS_REGIMES, BiasModel, alarm_level
from monitor.model.lever import (
    LeverModel,
    LeverWindow,
    fit_lever_scale,
    lever_direction,
    lever_directions,
    lever_series,
)
from monitor.model.modelfile import load_model, save_model


def _data(seed: int, n: int = 800, n_out: int = 4):
    """Residuals with NaN rows and commands that are raising, lowering and neither."""
    rng = np.random.default_rng(seed)
    e = rng.normal(0.0, 1.0, (n, n_out)) * rng.uniform(0.1, 3.0, n_out)
    e[:, 0] += rng.normal(0.0, 0.5)  # an offset on PP so that the means are not ~0
    e[rng.random(n) < 0.05, rng.integers(0, n_out)] = np.nan  # missing samples pause
    spool = rng.choice([-100.0, -90.0, -80.0, -50.0, 0.0, 40.0, 80.0, 80.5, 95.0], n)
    scale = rng.uniform(0.5, 2.0, 2)
    return e, spool, scale


@pytest.mark.parametrize("seed", [1, 2, 3, 4])
def test_series_matches_the_definition(seed: int) -> None:
    e, spool, scale = _data(seed)
    lever = LeverModel(60, 7, 0, scale, 1.0)
    got = lever_series(e, lever_directions(spool), lever)
    want = lever_statistic(e, spool, 0, scale, 60, 7)
    assert np.array_equal(np.isnan(got), np.isnan(want))
    ok = np.isfinite(want)
    assert ok.sum() > 500
    np.testing.assert_allclose(got[ok], want[ok], rtol=1e-9, atol=1e-12)


def test_series_matches_the_definition_on_another_output_and_sparse_commands() -> None:
    """Output 2 watched, full lever rare: many samples where no direction counts (NaN)."""
    e, _, scale = _data(5, n=1500, n_out=3)
    rng = np.random.default_rng(5)
    spool = np.where(rng.random(1500) < 0.12, rng.choice([-99.0, 99.0], 1500), 10.0)
    lever = LeverModel(40, 5, 2, scale, 1.0)
    got = lever_series(e, lever_directions(spool), lever)
    want = lever_statistic(e, spool, 2, scale, 40, 5)
    assert np.array_equal(np.isnan(got), np.isnan(want))
    ok = np.isfinite(want)
    assert 100 < ok.sum() < 1400
    np.testing.assert_allclose(got[ok], want[ok], rtol=1e-9, atol=1e-12)


def test_a_shortfall_only_series_matches_the_definition() -> None:
    """``sign`` 1 (L on a section's flow): only a positive mean (predicted above measured)
    counts, a negative one is 0, the same kernel live and batch."""
    e, spool, scale = _data(6, n=1500, n_out=3)
    lever = LeverModel(50, 5, 2, scale, 1.0, sign=1)
    got = lever_series(e, lever_directions(spool), lever)
    want = lever_statistic(e, spool, 2, scale, 50, 5, sign=1)
    assert np.array_equal(np.isnan(got), np.isnan(want))
    ok = np.isfinite(want)
    assert (want[ok] == 0).sum() > 50 and (want[ok] > 0).sum() > 50  # both signs occur
    np.testing.assert_allclose(got[ok], want[ok], rtol=1e-9, atol=1e-12)
    window = LeverWindow(lever)
    live = np.array([window.push(e[i], int(d)) for i, d in enumerate(lever_directions(spool))])
    np.testing.assert_array_equal(live, got)
    assert LeverModel.from_dict(lever.to_dict()).sign == 1
    assert "sign" not in LeverModel(50, 5, 2, scale).to_dict()  # two-sided files unchanged


def test_live_window_gives_the_series_numbers() -> None:
    """The ticker's one-sample pushes and the offline series give the very same numbers."""
    e, spool, scale = _data(6, n=3000)
    lever = LeverModel(200, 10, 0, scale, 1.0)
    directions = lever_directions(spool)
    live = LeverWindow(lever)
    pushed = np.array([live.push(e[i], int(directions[i])) for i in range(len(e))])
    series = lever_series(e, directions, lever)
    assert np.array_equal(np.isnan(pushed), np.isnan(series))
    ok = np.isfinite(series)
    assert ok.sum() > 2000
    assert np.array_equal(pushed[ok], series[ok])


def test_directions_split_at_80_percent() -> None:
    spool = np.array([0.0, 80.0, 80.0001, 100.0, -80.0, -80.0001, -100.0, 79.9, np.nan])
    want = [0, 0, 1, 1, 0, 2, 2, 0, 0]
    got = lever_directions(spool)
    assert got.dtype == np.int64
    assert list(got) == want
    assert [lever_direction(float(s)) for s in spool] == want


# Worked on paper: window 4, min_count 2, output 0, scale (1, 2); NaN in output 1 at sample 2.
HAND_SPOOL = [90.0, -90.0, 90.0, 50.0, 90.0, -85.0, 80.0, 100.0, -100.0, 95.0, -81.0]
HAND_E0 = [1.0, -2.0, 3.0, 5.0, 0.5, -4.0, 7.0, 2.5, 1.0, -1.5, -5.0]
HAND_L = [
    np.nan,  # 0: 1 valid sample so far
    np.nan,  # 1: 2 valid
    np.nan,  # 2: residual missing (NaN in output 1): skipped
    np.nan,  # 3: 3 valid (samples 0, 1, 3)
    0.75,  # 4: window {0,1,3,4}; raising {0,4}: (1 + 0.5) / 2 = 0.75; lowering {1}: 1 < 2
    1.5,  # 5: window {1,3,4,5}; raising {4}: too few; lowering {1,5}: |(-2 - 4) / 2| / 2 = 1.5
    np.nan,  # 6: window {3,4,5,6} (80.0 is direction 0); raising {4}, lowering {5}: none
    1.5,  # 7: window {4,5,6,7}; raising {4,7}: (0.5 + 2.5) / 2 = 1.5; lowering {5}: too few
    0.75,  # 8: window {5,6,7,8}; raising {7}; lowering {5,8}: |(-4 + 1) / 2| / 2 = 0.75
    0.5,  # 9: window {6,7,8,9}; raising {7,9}: (2.5 - 1.5) / 2 = 0.5; lowering {8}
    1.0,  # 10: window {7,8,9,10}; raising 0.5; lowering {8,10}: |(1 - 5) / 2| / 2 = 1.0; max
]


def _hand():
    e = np.zeros((len(HAND_E0), 2))
    e[:, 0] = HAND_E0
    e[2, 1] = np.nan
    return e, np.array(HAND_SPOOL)


def test_hand_worked_sequence() -> None:
    e, spool = _hand()
    assert list(lever_directions(spool)) == [1, 2, 1, 0, 1, 2, 0, 1, 2, 1, 2]
    lever = LeverModel(4, 2, 0, np.array([1.0, 2.0]), 1.0)
    got = lever_series(e, lever_directions(spool), lever)
    np.testing.assert_array_equal(got, np.array(HAND_L))
    np.testing.assert_array_equal(lever_statistic(e, spool, 0, [1.0, 2.0], 4, 2), HAND_L)
    live = LeverWindow(lever)
    pushed = [live.push(e[i], lever_direction(float(spool[i]))) for i in range(len(e))]
    np.testing.assert_array_equal(np.array(pushed), np.array(HAND_L))


def _cycles(n: int = 3000):
    """Lever cycles of 3 s at 100 Hz: 1 s raising at 95 %, 0.5 s at 30 %, 1 s lowering at
    -95 %, 0.5 s at -30 %."""
    one = np.concatenate(
        [np.full(100, 95.0), np.full(50, 30.0), np.full(100, -95.0), np.full(50, -30.0)]
    )
    return np.resize(one, n)


def test_a_steady_pp_offset_at_full_lever_raises_l_in_proportion() -> None:
    spool = _cycles()
    raising = spool > 80.0
    lever = LeverModel(600, 100, 0, np.array([0.5, 2.0]), 1.0)
    d = lever_directions(spool)
    for offset in (0.1, 0.2, 0.4):
        e = np.zeros((len(spool), 4))
        e[raising, 0] = offset  # PP reads `offset` high while raising, exact elsewhere
        L = lever_series(e, d, lever)
        assert np.all(np.isnan(L[:599])) and np.all(np.isfinite(L[599:]))
        # Every full window holds >= 200 raising samples, all offset: |mean| / scale[0].
        np.testing.assert_allclose(L[599:], offset / 0.5, rtol=1e-12)
    e = np.zeros((len(spool), 4))
    e[spool < -80.0, 0] = -0.4  # lowering: |-0.4| / 2.0
    np.testing.assert_allclose(lever_series(e, d, lever)[599:], 0.2, rtol=1e-12)


def test_residuals_elsewhere_leave_l_unchanged() -> None:
    """Another output's residual, or PP's at commands within +-80 %, do not move L."""
    rng = np.random.default_rng(9)
    spool = _cycles()
    d = lever_directions(spool)
    e = rng.normal(0.0, 0.3, (len(spool), 4))
    lever = LeverModel(600, 100, 0, np.array([1.0, 1.5]), 1.0)
    base = lever_series(e, d, lever)
    assert np.isfinite(base[599:]).all()
    other = e.copy()
    other[:, 1:] += 5.0  # PA, PB, QP all far off
    np.testing.assert_array_equal(lever_series(other, d, lever), base)
    partial = e.copy()
    partial[np.abs(spool) <= 80.0, 0] += 5.0  # PP far off, but only at +-30 %
    np.testing.assert_array_equal(lever_series(partial, d, lever), base)


@pytest.mark.parametrize(
    "args",
    [
        (0, 1, 0, [1.0, 1.0]),  # window
        (10, 0, 0, [1.0, 1.0]),  # min_count
        (10, 11, 0, [1.0, 1.0]),  # min_count beyond the window: L never defined
        (10, 2, -1, [1.0, 1.0]),  # output
        (10, 2, 0, [1.0]),  # scale: one per direction
        (10, 2, 0, [1.0, 0.0]),  # scale: positive
        (10, 2, 0, [1.0, np.nan]),
    ],
)
def test_bad_settings_are_a_config_error(args) -> None:
    window, min_count, output, scale = args
    with pytest.raises(ConfigError):
        LeverModel(window, min_count, output, np.array(scale), 1.0)
    assert issubclass(ConfigError, ValueError)


def test_to_dict_round_trip() -> None:
    lever = LeverModel(6000, 100, 0, np.array([0.25, 0.75]), 2.0)
    d = json.loads(json.dumps(lever.to_dict()))  # as the model file's JSON header holds it
    back = LeverModel.from_dict(d)
    assert (back.window_n, back.min_count, back.output, back.l0) == (6000, 100, 0, 2.0)
    assert np.array_equal(back.scale, lever.scale)
    assert back.to_dict() == lever.to_dict()


def test_fit_scale_by_hand() -> None:
    """Window 4, min_count 2, output 1 (output 0 is ignored, 50 throughout).
    Recording A, spool (90, 90, -90, 0, -90), e1 (1, 3, -1, 100, -2):
      window at 3 {0..3}: raising {0,1} mean 2; lowering {2} too few;
      window at 4 {1..4}: raising {1} too few; lowering {2,4} |(-1 - 2) / 2| = 1.5.
    Recording B, spool (-90, -90, 90, 90), e1 (-5, 0, 0.5, 0.5):
      window at 3: raising 0.5, lowering |(-5 + 0) / 2| = 2.5.
    Per direction the largest: raising 2, lowering 2.5."""
    a = np.column_stack([np.full(5, 50.0), [1.0, 3.0, -1.0, 100.0, -2.0]])
    b = np.column_stack([np.full(4, 50.0), [-5.0, 0.0, 0.5, 0.5]])
    da = lever_directions(np.array([90.0, 90.0, -90.0, 0.0, -90.0]))
    db = lever_directions(np.array([-90.0, -90.0, 90.0, 90.0]))
    scale = fit_lever_scale([a, b], [da, db], 4, 2, 1)
    np.testing.assert_array_equal(scale, [2.0, 2.5])


def test_fit_scale_is_the_per_direction_max_of_the_definition() -> None:
    """Each direction on its own: the definition with unit scales, the other direction's
    commands set to 0 (still valid samples, counted for neither)."""
    recs = [_data(s, n=900) for s in (11, 12)]
    es = [r[0] for r in recs]
    spools = [r[1] for r in recs]
    got = fit_lever_scale(es, [lever_directions(s) for s in spools], 60, 7, 0)
    want = []
    for keep in (lambda s: s > 80.0, lambda s: s < -80.0):  # raising, lowering
        best = 0.0
        for e, s in zip(es, spools, strict=True):
            only = np.where(keep(s), s, 0.0)
            best = max(best, np.nanmax(lever_statistic(e, only, 0, [1.0, 1.0], 60, 7)))
        want.append(best)
    np.testing.assert_allclose(got, want, rtol=1e-9)


def test_fit_scale_leaves_out_a_direction_never_held_at_full_lever() -> None:
    """A direction the held-out data never holds at full lever for ``min_count`` samples
    within a full window gets an infinite scale (left out); neither direction: no L."""
    e = np.ones((20, 1))
    never_lowered = lever_directions(np.full(20, 90.0))
    np.testing.assert_array_equal(fit_lever_scale([e], [never_lowered], 4, 2, 0), [1.0, np.inf])
    # Two lowering samples, but only before the first full window of 4 (3 samples long).
    short = lever_directions(np.array([-90.0, -90.0, 90.0]))
    with pytest.raises(InputFileError, match="either direction"):
        fit_lever_scale([e[:3]], [short], 4, 2, 0)
    # ... and the same with the window reached: fits.
    ok = lever_directions(np.array([-90.0, -90.0, 90.0, 90.0]))
    np.testing.assert_array_equal(fit_lever_scale([e[:4]], [ok], 4, 2, 0), [1.0, 1.0])
    # A shortfall-only L whose lowering windows were all in excess (mean -1): no shortfall
    # to scale by, so lowering is left out too.
    np.testing.assert_array_equal(
        fit_lever_scale([np.where(ok == 2, -1.0, 1.0)[:, None]], [ok], 4, 2, 0, sign=1),
        [1.0, np.inf],
    )


def test_a_direction_left_out_never_counts_live_or_batch() -> None:
    """Lowering left out (infinite scale): L is the raising direction's alone, NaN where
    only lowering counts, as the definition's twin says; live == batch."""
    e, spool, _ = _data(7, n=1500, n_out=3)
    scale = np.array([0.8, np.inf])
    lever = LeverModel(50, 5, 2, scale, 2.0, sign=1)
    got = lever_series(e, lever_directions(spool), lever)
    want = lever_statistic(e, spool, 2, scale, 50, 5, sign=1)
    assert np.array_equal(np.isnan(got), np.isnan(want))
    raising_only = lever_statistic(e, np.where(spool > 0, spool, 0.0), 2, [0.8, 1.0], 50, 5, 1)
    np.testing.assert_allclose(got, raising_only, rtol=1e-9, atol=1e-12, equal_nan=True)
    window = LeverWindow(lever)
    live = np.array([window.push(e[i], int(d)) for i, d in enumerate(lever_directions(spool))])
    np.testing.assert_array_equal(live, got)
    # The file's header is strict JSON (null, not Infinity) and reads back the same.
    back = LeverModel.from_dict(json.loads(json.dumps(lever.to_dict(), allow_nan=False)))
    np.testing.assert_array_equal(back.scale, scale)


J = np.array([np.nan, 1.0, 1.0, 1.0, 3.0, 1.0])  # / eps0 2: nan, 0.5, 0.5, 0.5, 1.5, 0.5
B = np.array([8.0, np.nan, 8.0, 8.0, 8.0, np.nan])  # / b0 4:  2,  nan, 2,   2,   2,   nan
LEV = np.array([9.0, 9.0, np.nan, 3.0, 12.0, np.nan])  # / l0 3: 3, 3,  nan, 1,   4,   nan


def _bias_b0_4():
    return BiasModel(10, 1, np.ones((N_BIAS_REGIMES, 1)), 4.0)


def test_alarm_level_with_lever_is_the_largest_ratio() -> None:
    level = alarm_level(J, 2.0, B, _bias_b0_4(), lever=(LEV, 3.0))
    assert np.isnan(level[0])  # J missing: NaN whatever B and L say
    assert level[3] == 2.0  # max(0.5, 2, 1)
    assert level[4] == 4.0  # max(1.5, 2, 4)
    assert level[5] == 0.5  # B and L both NaN: J alone
    # Without lever, as before: J alone where B is NaN.
    assert list(alarm_level(J, 2.0, B, _bias_b0_4())[1:]) == [0.5, 2.0, 2.0, 2.0, 0.5]


def test_alarm_level_uses_each_finite_statistic() -> None:
    """A statistic still filling its window (NaN) leaves the others in charge: at sample 1
    (B NaN) the level is max(J/eps0 0.5, L/l0 3) = 3, at sample 2 (L NaN) max(0.5, B/b0
    2) = 2; the live ticker does the same sample by sample."""
    level = alarm_level(J, 2.0, B, _bias_b0_4(), lever=(LEV, 3.0))
    assert list(level[1:3]) == [3.0, 2.0]


def test_model_file_keeps_the_lever(tmp_path, model) -> None:
    lever = LeverModel(6000, 100, 0, np.array([0.3, 0.7]), 2.0)
    with_lever = dataclasses.replace(model, lever=lever)
    path = tmp_path / "m.npz"
    save_model(path, with_lever)
    back = load_model(path)
    assert back.lever is not None
    assert back.lever.to_dict() == lever.to_dict()
    assert np.array_equal(back.lever.scale, lever.scale)
    assert back.header() == with_lever.header()
    assert back.header()["lever"] == lever.to_dict()
    # Without it, no "lever" key and None back.
    save_model(path, dataclasses.replace(model, lever=None))
    again = load_model(path)
    assert again.lever is None and "lever" not in again.header()


GOOD = {"window_n": 6000, "min_count": 100, "output": 0, "scale": [0.3, 0.7], "l0": 2.0}


def test_crafted_good_lever_header_loads(tmp_path) -> None:
    m = load_model(craft_model(tmp_path, set_key("lever", GOOD)))
    assert m.lever is not None and m.lever.to_dict()["window_n"] == 6000


@pytest.mark.parametrize(
    "change",
    [{"window_n": 0}, {"l0": -1.0}, {"scale": [0.3]}, {"output": 4}, {"min_count": 0}],
)
def test_a_malformed_lever_header_is_a_model_file_error_naming_lever(tmp_path, change) -> None:
    with pytest.raises(ModelFileError, match="lever") as exc:
        load_model(craft_model(tmp_path, set_key("lever", {**GOOD, **change})))
    assert "crafted.npz" in str(exc.value) and "\n" not in str(exc.value)


def test_detect_summary_has_max_l_and_lever_threshold(model) -> None:
    """Offline detection: L is the definition over the detection's residuals and SpoolCmd;
    the summary's max_L its largest finite value, lever_threshold l0 (both null without)."""
    from monitor.config.settings import load_config
    from monitor.detection.offline import detect
    from monitor.sim.cycles import make_cycle
    from monitor.sim.machine import load_machine
    from monitor.sim.simulate import simulate

    cfg = load_config()
    rec = simulate(make_cycle("boom", 30.0, 5), load_machine(), seed=5)
    s = detect(dataclasses.replace(model, lever=None), rec, cfg.alarm, cfg.horizon).summary
    assert s["max_L"] is None and s["lever_threshold"] is None
    lever = LeverModel(100, 1, 0, np.array([1.0, 2.0]), 2.0)  # 1 s window, min_count 1
    det = detect(dataclasses.replace(model, lever=lever), rec, cfg.alarm, cfg.horizon)
    want = lever_statistic(det.residual, rec.columns["SpoolCmd"], 0, [1.0, 2.0], 100, 1)
    assert np.isfinite(want).sum() > 100
    s = det.summary
    assert s["lever_threshold"] == 2.0
    assert s["max_L"] == pytest.approx(np.nanmax(want), rel=1e-9)
    assert json.loads(json.dumps(s))["max_L"] == s["max_L"]  # the --json summary


def _boom_runs(seeds):
    from monitor.sim.cycles import make_cycle
    from monitor.sim.machine import load_machine
    from monitor.sim.simulate import simulate

    return [simulate(make_cycle("boom", 120.0, s), load_machine(), seed=s) for s in seeds]


@pytest.fixture(scope="module")
def boom_runs():
    """Eight normal boom runs of 120 s: 2 to fit, 6 held out (enough for B and L)."""
    return _boom_runs(range(1, 9))


def _train(fit, held_out):
    from monitor.training.settings import (
        DGRNNSettings,
        IsolationSettings,
        StatisticSettings,
        TrainConfig,
    )
    from monitor.training.train import train

    said: list[str] = []
    cfg = TrainConfig(
        DGRNNSettings(max_patterns=400),
        # L's own mechanics: B (which L needs) kept whatever minutes of data support it
        statistics=StatisticSettings(support_check=False),
        isolation=IsolationSettings("none"),
    )
    return train(fit, cfg, said.append, held_out=held_out), said


def test_training_puts_l0_at_twice_the_held_out_max(boom_runs) -> None:
    """The scales are the held-out maxima, so the held-out L peaks at exactly 1, and the max
    rule with factor 2 puts l0 at 2."""
    m, said = _train(boom_runs[:2], boom_runs[2:])
    assert m.bias is not None and m.lever is not None
    assert m.lever.output == list(m.dgrnn.spec.outputs).index("PP")
    assert (m.lever.window_n, m.lever.min_count) == (6000, 100)  # 60 s, 1 s at 100 Hz
    assert m.lever.l0 == pytest.approx(2.0, rel=1e-12)
    assert np.all(m.lever.scale > 0) and m.lever.scale.shape == (2,)
    assert not m.training["lever"].startswith("off")
    assert any("full-lever statistic" in line for line in said)


def test_held_out_data_never_lowering_at_full_lever_trains_l_on_raising(boom_runs) -> None:
    import copy

    held = [copy.deepcopy(r) for r in boom_runs[2:]]
    for r in held:  # the lever never pushed beyond -80 %
        r.columns["SpoolCmd"] = np.maximum(r.columns["SpoolCmd"], -79.0)
    m, _ = _train(boom_runs[:2], held)
    assert m.bias is not None and m.lever is not None
    assert np.isfinite(m.lever.scale[0]) and m.lever.scale[1] == np.inf
    assert m.training["lever"].startswith("on")


def test_short_held_out_data_trains_without_lever(boom_runs) -> None:
    """Too little held-out data for the bias statistic (one run of 120 s): L is off too."""
    m, _ = _train(boom_runs[:2], boom_runs[2:3])
    assert m.bias is None
    assert m.lever is None
    assert m.training["lever"].startswith("off")


def test_l_watches_pp_with_b_and_a_sections_flow_shortfall_on_its_own() -> None:
    """A loop on its own pump: L on PP, two-sided, only with B on (as it always was).  A
    section of a shared load-sensing pump (PP an input): L on QP, a shortfall only, over 3 s
    of full lever, asked with B but not resting on B's support."""
    from monitor.model.lever import Lever
    from monitor.training.settings import DGRNNSettings, TrainConfig

    own = TrainConfig()
    pp = Lever.configure(own, ("PP", "PA", "PB", "QP"), {"J", "B"})
    assert isinstance(pp, Lever) and (pp.output, pp.sign, pp.min_count) == (0, 0, 100)
    assert isinstance(Lever.configure(own, ("PP", "PA", "PB", "QP"), {"J"}), str)
    section = TrainConfig(DGRNNSettings(preset="section"))
    qp = Lever.configure(section, ("PA", "PB", "QP"), {"J"})  # the bucket's B is off
    assert isinstance(qp, Lever) and (qp.output, qp.sign, qp.min_count) == (2, 1, 300)
    paper = TrainConfig(DGRNNSettings(preset="paper"))  # no B asked: no L either
    assert isinstance(Lever.configure(paper, ("PA", "PB", "QP"), {"J"}), str)
