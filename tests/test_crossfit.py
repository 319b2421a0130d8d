"""Cross-fitted thresholds (monitor.training.crossfit): every normal sample is judged by a
model that never saw it, and `monitor train` uses them when the data allows."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from naive import embed, grnn_predict

from monitor.model.dgrnn import DGRNN
from monitor.model.grnn import GRNN
from monitor.model.modelfile import MonitorModel
from monitor.model.spec import DGRNNSpec, Normalizer, table
from monitor.model.threshold import ThresholdRule
from monitor.sim.cycles import make_cycle
from monitor.sim.machine import load_machine
from monitor.sim.simulate import simulate
from monitor.training.crossfit import cross_fitted_residuals, fold_ids, n_blocks
from monitor.training.settings import (
    IsolationSettings,
    StatisticSettings,
    ThresholdSettings,
    TrainConfig,
)
from monitor.training.train import floor_thresholds, normal_residuals, train


def test_blocks_are_dealt_round_robin_across_recordings() -> None:
    # By hand: 250 samples in blocks of 100 are blocks 0, 1, 2 (the last one short); the
    # next recording's blocks continue the count, 3 and 4, so they go to folds 0 and 1.
    a, b = fold_ids([250, 130], folds=3, block_n=100)
    assert list(np.unique(a[:100])) == [0] and list(np.unique(a[100:200])) == [1]
    assert list(np.unique(a[200:])) == [2]
    assert list(np.unique(b[:100])) == [0] and list(np.unique(b[100:])) == [1]
    assert n_blocks([250, 130], 100) == 5


def _recordings(seconds: float, seeds: tuple[int, ...]) -> list:
    return [simulate(make_cycle("boom", seconds, s), load_machine(), seed=s) for s in seeds]


def test_each_block_is_predicted_from_the_other_folds_only() -> None:
    # Reference written apart: for every fold, eq. 4 (tests/naive.py) over the lag-embedded
    # rows of the other folds' blocks (adjacent ones are one stretch of data), with the full
    # model's sigma and no thinning.
    spec = DGRNNSpec.preset("paper")
    recs = _recordings(12.0, (5, 6))
    tables = [table(r, spec.variables) for r in recs]
    norm = Normalizer().fit(np.concatenate(tables), spec.variables)
    zs = [norm.transform(t) for t in tables]
    grnn = GRNN(thinning="none", max_patterns=None, exclude_neighbours=5)
    model = MonitorModel(DGRNN(spec, grnn).fit(zs), norm, 100, ThresholdRule(), math.nan, math.nan)
    folds, block_n = 3, 250
    got = cross_fitted_residuals(model, zs, recs, folds, block_n, normal_residuals)

    ids = fold_ids([len(z) for z in zs], folds, block_n)
    for k in range(folds):
        X, Y = [], []
        for z, f in zip(zs, ids, strict=True):
            run: list[np.ndarray] = []  # consecutive blocks of other folds: one stretch
            for start in [*range(0, len(z), block_n), len(z)]:
                if start < len(z) and f[start] != k:
                    run.append(z[start : start + block_n])
                elif run:
                    x, y, _ = embed(spec, np.concatenate(run))
                    X.append(x)
                    Y.append(y)
                    run = []
        P, Py = np.concatenate(X), np.concatenate(Y)
        for z, f, e in zip(zs, ids, got, strict=True):
            rows = np.flatnonzero(f == k)
            rows = rows[rows >= spec.max_lag]
            x, y, t = embed(spec, z)
            pick = np.isin(t, rows)
            want = grnn_predict(x[pick], P, Py, grnn.sigma_) - y[pick]
            # atol: the detector's cut-off index leaves out weights below its cut (1e-9 here)
            np.testing.assert_allclose(e[t[pick]], want, rtol=0, atol=1e-7)
    # Out of fold is out of sample: worse than the full model's in-sample residuals.
    inside = np.concatenate([normal_residuals(model, r) for r in recs])
    assert np.nanmean(np.concatenate(got) ** 2) > 1.5 * np.nanmean(inside**2)


@pytest.fixture(scope="module")
def commissioned() -> tuple[MonitorModel, list[str], list]:
    recs = _recordings(300.0, (11, 12))  # 10 blocks of 60 s: enough for 4 folds (8)
    said: list[str] = []
    return (
        train(
            recs,
            TrainConfig(thresholds=ThresholdSettings(folds=4), isolation=IsolationSettings("none")),
            said.append,
        ),
        said,
        recs,
    )


def test_train_cross_fits_when_the_data_allows_and_says_so(commissioned) -> None:
    m, said, recs = commissioned
    assert m.training["validation"] == "cross-fitted, 4 folds of 60 s blocks"
    assert m.training["patterns_from"] == [r.source for r in recs]
    assert any("fold 4/4" in line for line in said)
    assert math.isfinite(m.eps0) and m.eps0 > 0
    # 10 minutes cross-fitted are enough for the bias statistic (8 minutes held out were not
    # available from 10 minutes before: a quarter held out is 2.5 minutes).
    assert m.bias is not None and math.isfinite(m.bias.b0)

    short: list[str] = []
    m = train(
        recs[:1],
        TrainConfig(
            thresholds=ThresholdSettings(folds=4),
            statistics=StatisticSettings(bias=False),
            isolation=IsolationSettings("none"),
        ),
        short.append,
    )
    assert m.training["validation"] == "held out"  # 5 blocks of 60 s, fewer than 8
    assert any("too short to cross-fit 4 folds" in line for line in short)


@pytest.mark.parametrize("folds", [1, 21, -2])
def test_fold_counts_outside_the_range_are_refused(folds: int) -> None:
    from monitor.errors import ConfigError

    with pytest.raises(ConfigError, match="folds must be"):
        ThresholdSettings(folds=folds)


def test_a_reference_floors_both_thresholds_and_never_lowers_them(commissioned) -> None:
    m, _, _ = commissioned
    own_eps0, own_b0 = m.eps0, m.bias.b0
    ref = replace(m, eps0=3.0 * own_eps0, bias=replace(m.bias, b0=0.5 * own_b0))
    floored = replace(m)
    note = floor_thresholds(floored, ref)
    assert floored.eps0 == 3.0 * own_eps0  # raised to the reference's
    assert floored.bias.b0 == own_b0  # already above the reference's: kept
    assert note == f"eps0 {own_eps0:.4g} -> {3.0 * own_eps0:.4g}"
    assert m.eps0 == own_eps0  # the model given is changed, not the one it was copied from


def test_a_reference_of_another_kind_is_refused_naming_both(commissioned) -> None:
    from monitor.errors import ConfigError

    m, _, _ = commissioned
    with pytest.raises(ConfigError, match=r"J window 6000\).*J window 3000"):
        floor_thresholds(replace(m), replace(m, window_n=6000))


def test_monitor_train_refuses_a_reference_of_another_preset_before_fitting(
    tmp_path, capsys
) -> None:
    from monitor.cli import main
    from monitor.resources import resource_path

    out = tmp_path / "m.npz"
    log = str(resource_path("replay", "normal.log"))
    rc = main(["train", log, "--preset", "paper", "--reference", "shipped", "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and not out.exists()
    assert not any("fitting" in line for line in err)  # refused before the long work
    assert "the reference model (PP/PA/PB/QP from" in err[-1]
    assert "does not match the model to train (QP from QP/PP/PA/PB" in err[-1]
