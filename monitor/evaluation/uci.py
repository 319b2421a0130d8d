"""DGRNN fault detection on the real ZeMA hydraulic rig (``monitor eval-uci``).

The rig (Helwig et al. 2015, UCI, CC BY 4.0) repeats one 60 s load cycle; each cycle is a
separate 1 Hz recording (loaded by :mod:`monitor.evaluation.uci_data`).  Method, per cycle:

- Signals in the paper's roles: PP = PS1 (pump outlet pressure, 135-192 bar, the highest
  pressure of the working circuit), QP = FS1 (working-circuit flow, 0-12 L/min, it follows the
  load steps), PA = PS2 (working pressure after the valve, 0-166 bar) and PB = PS3 (low-side
  pressure, 0-4 bar).  PS4 is left out: it reads 0 bar in 876 of the 1543 cycles.  PS5/PS6
  and FS2 belong to the cooling/filtration circuit.
- Presets: ``paper`` is eq. 11 with those names (FS1 from FS1, PS1, PS2, PS3 at t-1, t-2).
  ``rig`` predicts all four from one kernel pass and adds exogenous inputs: motor power EPS1
  at t and t-1 (the pump's input power) and the time in the cycle [s] (the load profile is a
  fixed command schedule that is not recorded; its time plays the part of the excavator's
  SpoolCmd).  ``rig_temp`` adds oil temperature TS1 at t.
- Lags stay inside a cycle (cycles are separate recordings): the first ``max_lag`` seconds
  of each cycle are not predicted.  One-step prediction (horizon 1).
- Sigma by leave-one-out with ``exclude_neighbours = 60`` samples, i.e. leave-one-*cycle*-out:
  within a cycle the 1 Hz samples of a steady load phase are near copies.
- J = eq. 9 per cycle with window N (chosen from ``WINDOWS``); a cycle alarms when its
  largest J exceeds eps0 = 2 J0, J0 = the largest per-cycle J on held-out healthy cycles
  (the ``max`` rule of :mod:`monitor.model.threshold`), or when the bias statistic B, each
  output's mean residual over each load phase (:mod:`monitor.evaluation.uci_bias`),
  exceeds b0.  The phase length (or none: J alone) is chosen with N on --train.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from monitor.errors import ConfigError
from monitor.evaluation.uci_bias import PHASES_S, CycleRule, cycle_b, phase_means
from monitor.evaluation.uci_data import (
    HEALTHY,
    J0_EVERY,
    SAMPLES_PER_CYCLE,
    RigCycles,
    holdout,
    load_rig,
    split,
)
from monitor.evaluation.uci_presets import (
    CYCLE_TIME,
    MIN_STD,
    UCI_PRESETS,
    WINDOWS,
)
from monitor.evaluation.uci_score import score, selection
from monitor.model.dgrnn import DGRNN, predict_series
from monitor.model.grnn import GRNN
from monitor.model.residual import window_j
from monitor.model.spec import DGRNNSpec, Normalizer
from monitor.model.threshold import ThresholdRule

#: The rig's sensors that play the paper's signal roles (the contract's names).
ROLES = {"PP": "PS1", "QP": "FS1", "PA": "PS2", "PB": "PS3"}

Progress = Callable[[str], None]


# --------------------------------------------------------------------------- data and split


def sensors_needed(presets: Sequence[str]) -> list[str]:
    names = {v for p in presets for v in UCI_PRESETS[p].variables if v != CYCLE_TIME}
    return sorted(names)


def _with_cycle_time(rc: RigCycles) -> RigCycles:
    rc.signals[CYCLE_TIME] = np.tile(np.arange(SAMPLES_PER_CYCLE, dtype=np.float64), (len(rc), 1))
    return rc


# --------------------------------------------------------------------------- model


def fit(spec: DGRNNSpec, rc: RigCycles, idx: np.ndarray) -> tuple[DGRNN, Normalizer]:
    """Normaliser on the pattern cycles (F0 statistics), then the DGRNN on them."""
    names = spec.variables
    norm = Normalizer(min_std=MIN_STD).fit(
        np.vstack([rc.cycle_table(names, i) for i in idx]), names
    )
    # exclude_neighbours = one cycle: LOO predicts each cycle from the other cycles.
    grnn = GRNN(exclude_neighbours=SAMPLES_PER_CYCLE, max_patterns=3000)
    model = DGRNN(spec, grnn).fit([norm.transform(rc.cycle_table(names, i), names) for i in idx])
    return model, norm


def cycle_residuals(model: DGRNN, norm: Normalizer, rc: RigCycles) -> np.ndarray:
    """Eq. 8 residuals (z-score units), (cycles, 60, outputs); NaN where not predicted.

    All cycles go through one parallel prediction call, separated by NaN rows so no lag
    reads across two cycles (a NaN input pauses prediction).
    """
    spec = model.spec
    names, nout = spec.variables, len(spec.outputs)
    pad = spec.rows_needed() - 1
    n, T = len(rc), SAMPLES_PER_CYCLE
    stack = np.full((n, pad + T, len(names)), np.nan)
    for j, name in enumerate(names):
        stack[:, pad:, j] = (rc.signals[name] - norm.mean_[j]) / norm.std_[j]
    Z = stack.reshape(-1, len(names))
    y_hat = predict_series(model, Z).reshape(n, pad + T, nout)[:, pad:]
    return y_hat - stack[:, pad:, :nout]


def cycle_j(e: np.ndarray, N: int) -> np.ndarray:
    """Eq. 9 J of each cycle (cycles, 60), the window restarting at each cycle (NaN until
    N + 1 residuals of that cycle exist)."""
    out = np.full(e.shape[:2], np.nan)
    for i in range(e.shape[0]):
        out[i] = window_j(e[i], N)
    return out


def max_j(j: np.ndarray) -> np.ndarray:
    """Largest J of each cycle (cycles,): the quantity the per-cycle alarm compares."""
    return np.nanmax(j, axis=1) if j.shape[0] else np.zeros(0)


def first_alarm_s(j: np.ndarray, eps0: float) -> np.ndarray:
    """Second of the cycle at which J first exceeds eps0 (NaN for cycles never alarmed)."""
    above = np.nan_to_num(j, nan=-np.inf) > eps0
    return np.where(above.any(axis=1), np.argmax(above, axis=1).astype(float), np.nan)


# --------------------------------------------------------------------------- evaluation


def evaluate(
    train_dir: Path,
    test_dir: Path,
    presets: Sequence[str] = tuple(UCI_PRESETS),
    windows: Sequence[int] = WINDOWS,
    rule: ThresholdRule | None = None,
    max_cycles: int | None = None,
    progress: Progress | None = None,
) -> dict[str, Any]:
    """Fit every preset on --train, choose (preset, N) on --train alone, score --test."""
    t_start = time.perf_counter()
    say = progress or (lambda _msg: None)
    rule = rule or ThresholdRule("max", factor=2.0)
    check_arguments(presets, windows, max_cycles)
    data = load(train_dir, test_dir, presets, max_cycles)
    say(
        f"loaded {len(data.train)} train cycles ({len(data.pat_idx)} healthy for patterns, "
        f"{len(data.j0_idx)} for J0) and {len(data.test)} test cycles in "
        f"{time.perf_counter() - t_start:.1f} s"
    )
    fits = {name: fit_preset(name, data, windows, rule, say) for name in presets}
    for fitted in fits.values():
        # Each preset is also scored with its own best N, so both are reported side by side.
        score_best(fitted, data, rule)
    chosen = choose(fits)
    return {
        **chosen_summary(fits[chosen], rule),
        "presets": {name: f.result for name, f in fits.items()},
        "split": split_summary(data, train_dir, test_dir),
        "healthy_definition": dict(HEALTHY) | {"cooler": "any", "stable": "any"},
        "counts": fits[chosen].result["test"]["counts"],
        "runtime_s": round(time.perf_counter() - t_start, 2),
        "data_source": "ZeMA hydraulic test rig, Helwig, Pignanelli & Schuetze, I2MTC 2015, "
        "UCI Machine Learning Repository, CC BY 4.0",
    }


def check_arguments(presets: Sequence[str], windows: Sequence[int], max_cycles: int | None) -> None:
    """ConfigError naming the preset, window or cycle count that cannot be evaluated."""
    for p in presets:
        if p not in UCI_PRESETS:
            raise ConfigError(f"unknown preset {p!r}; choose from {', '.join(UCI_PRESETS)}")
    if not presets or not windows or min(windows) < 0:
        raise ConfigError("need at least one preset and windows N >= 0")
    if max(windows) + 1 > SAMPLES_PER_CYCLE - max(UCI_PRESETS[p].max_lag for p in presets):
        raise ConfigError(f"window N={max(windows)} does not fit in a 60 s cycle")
    if max_cycles is not None and max_cycles < 10:
        raise ConfigError(f"--max-cycles {max_cycles}: need at least 10")


@dataclass(frozen=True)
class RigData:
    """The --train and --test cycles, and --train's healthy cycles for patterns and J0."""

    train: RigCycles
    test: RigCycles
    split_info: dict[str, Any]
    pat_idx: np.ndarray
    j0_idx: np.ndarray


def load(
    train_dir: Path, test_dir: Path, presets: Sequence[str], max_cycles: int | None
) -> RigData:
    """Both folders (once when they are the same), split and given each cycle's time."""
    sensors = sensors_needed(presets)
    same = Path(train_dir).resolve() == Path(test_dir).resolve()
    train_all = load_rig(train_dir, sensors)
    test_all = train_all if same else load_rig(test_dir, sensors)
    train, test, split_info = split(train_all, test_all, same, max_cycles)
    _with_cycle_time(train)
    _with_cycle_time(test)
    pat_idx, j0_idx = holdout(train)
    return RigData(train, test, split_info, pat_idx, j0_idx)


@dataclass
class PresetFit:
    """One preset fitted on --train: its result record, J per window on both sides and B's
    phase means per phase length (None: J alone) on both sides."""

    name: str
    result: dict[str, Any]
    jtests: dict[int, tuple[np.ndarray, np.ndarray]]
    means: dict[int | None, tuple[Any, Any]]


def fit_preset(
    name: str, data: RigData, windows: Sequence[int], rule: ThresholdRule, say: Progress
) -> PresetFit:
    """Fit the preset on the pattern cycles and score every (N, phase) on --train alone."""
    t0 = time.perf_counter()
    spec = UCI_PRESETS[name]
    model, norm = fit(spec, data.train, data.pat_idx)
    e_train = cycle_residuals(model, norm, data.train)
    e_test = cycle_residuals(model, norm, data.test)
    # J alone first: on a tie the simpler rule stays.  The paper preset is the paper's
    # J alone, as `monitor train --preset paper` has no B.
    phases = (None,) if name == "paper" else (None, *PHASES_S)
    means: dict[int | None, tuple[Any, Any]] = {
        p: (None, None) if p is None else (phase_means(e_train, p), phase_means(e_test, p))
        for p in phases
    }
    sel = {}
    jtests = {}
    for N in windows:
        jm = max_j(cycle_j(e_train, N))
        jtests[N] = (jm, cycle_j(e_test, N))
        for phase in phases:
            key = str(N) if phase is None else f"{N}+B{phase}s"
            sel[key] = {
                "window_N": N,
                "bias_phase_s": phase,
                **selection(jm, means[phase][0], data.train, data.j0_idx, rule),
            }
    g = model.grnn
    result = {
        "spec": spec.to_dict(),
        "sigma": g.sigma_,
        "sigma_rule": f"{g.sigma_rule_} (leave-one-cycle-out: exclude_neighbours="
        f"{g.exclude_neighbours_})",
        "loo_error": g.loo_error_,
        "thinning": g.thinning_,
        "normalizer": norm.to_dict(),
        "selection_on_train": sel,
        "fit_and_predict_s": round(time.perf_counter() - t0, 2),
    }
    say(
        f"preset {name}: sigma {g.sigma_:.4g}, {g.thinning_['n_patterns']} patterns, "
        f"best train score {max(s['score'] for s in sel.values()):.3f} "
        f"({time.perf_counter() - t0:.1f} s)"
    )
    return PresetFit(name, result, jtests, means)


def choose(fits: dict[str, PresetFit]) -> str:
    """The preset with the best --train score; on a tie (within 1e-12) the first tried."""
    best: tuple[float, str] | None = None
    for name, fitted in fits.items():
        for s in fitted.result["selection_on_train"].values():
            if best is None or s["score"] > best[0] + 1e-12:
                best = (s["score"], name)
    assert best is not None
    return best[1]


def score_best(fitted: PresetFit, data: RigData, rule: ThresholdRule) -> None:
    """Score --test with the preset's best (N, phase) on --train, into its result."""
    res, test = fitted.result, data.test
    sel = res["selection_on_train"]
    # The best score; on a tie the first tried (smaller N, J alone before B).
    pick = sel[max(sel, key=lambda k: (sel[k]["score"], -list(sel).index(k)))]
    N, phase = pick["window_N"], pick["bias_phase_s"]
    jm_train, j_test = fitted.jtests[N]
    jm_test = max_j(j_test)
    m_train, m_test = fitted.means[phase]
    cr = CycleRule.fit(jm_train, m_train, data.j0_idx, rule)
    j0, eps0 = rule.eps0(jm_train[data.j0_idx])
    res["window_N"] = N
    res["bias_phase_s"] = phase
    res["J0"], res["eps0"] = j0, eps0
    res["b0"] = None if phase is None else cr.b0
    t = res["test"] = score(test, cr.alarms(jm_test, m_test))
    # How close the healthy test cycles came to the threshold (1.0 = at eps0).
    t["max_J_healthy_over_eps0"] = float(np.max(jm_test[test.healthy], initial=0) / eps0)
    t["max_B_healthy_over_b0"] = (
        None
        if m_test is None or cr.scale is None
        else float(np.max(cycle_b(m_test[test.healthy], cr.scale), initial=0) / cr.b0)
    )
    # Detection delay within the cycle: J needs N + 1 residuals, so >= max_lag + N s; B
    # is judged at the end of a phase.
    fa = first_alarm_s(j_test, eps0)
    if m_test is not None:
        fa = np.fmin(fa, cr.first_b_alarm_s(m_test, phase))
    fa = fa[~test.healthy]
    t["median_first_alarm_s_in_cycle"] = float(np.nanmedian(fa)) if np.isfinite(fa).any() else None


def chosen_summary(fitted: PresetFit, rule: ThresholdRule) -> dict[str, Any]:
    """The contract's rates of the chosen preset on --test, and its model."""
    ch, chosen = fitted.result, fitted.name
    return {
        "healthy_false_alarm_rate": ch["test"]["healthy_false_alarm_rate"],
        "detection": ch["test"]["detection"],
        "any_fault_detection": ch["test"]["any_fault_detection"],
        "by_condition": ch["test"]["by_condition"],
        "default_preset": chosen,
        "chosen_by": "largest (detection - cross-validated false-alarm rate) on --train: "
        "its faulty cycles and its J0 cycles; --test labels only score",
        "model": {
            "preset": chosen,
            "roles": ROLES,
            "outputs": list(UCI_PRESETS[chosen].outputs),
            "exogenous": list(UCI_PRESETS[chosen].exogenous),
            "sigma": ch["sigma"],
            "window_N": ch["window_N"],
            "J0": ch["J0"],
            "eps0": ch["eps0"],
            "bias_phase_s": ch["bias_phase_s"],
            "b0": ch["b0"],
            "threshold_rule": {
                **rule.to_dict(),
                "J0_over": "largest J of each held-out healthy --train cycle",
            },
            "alarm": "a cycle alarms when its largest J (eq. 9, window N+1 s) exceeds eps0, or "
            "(with bias_phase_s) when B, an output's mean residual over a load phase over "
            "its largest held-out healthy value, exceeds b0",
        },
    }


def split_summary(data: RigData, train_dir: Path, test_dir: Path) -> dict[str, Any]:
    """Which cycles trained, set J0 and were scored."""
    train = data.train
    return {
        **data.split_info,
        "train_folder": str(train_dir),
        "test_folder": str(test_dir),
        "train_cycles": len(train),
        "pattern_cycles": len(data.pat_idx),
        "j0_cycles": len(data.j0_idx),
        "train_fault_cycles_for_selection": int((~train.healthy).sum()),
        "test_cycles": len(data.test),
        "j0_rule": f"every {J0_EVERY}rd healthy --train cycle per cooler state",
    }
