"""Benchmark 3: ``monitor detect`` throughput on a long log against the pipeline a user would
write with the usual tools: python-can's LogReader, cantools decoding and pyGRNN.

Ours is timed in-process and warm (numba's on-disk cache loaded, as after the first run):
model load with its index build, the bulk candump path, prediction, J, the alarm machine
and the events file.  The CLI's cold wall time (interpreter start and imports included) is
reported beside it.  The reference runs on a slice of a few minutes (pyGRNN needs about a
millisecond per query at 20,000 patterns) and is stated per frame; it does the same work:
latest value per signal on the 10 ms grid, z-score, lag embedding, GRNN per output (batches
of 1,000 queries), residual bound, J over the same window and the same debounced threshold.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import subprocess
import sys
import tempfile
import time
import warnings
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, cast

import can
import cantools
import numpy as np

from monitor.config.settings import load_config
from monitor.detection.offline import detect
from monitor.model.modelfile import Isolation, MonitorModel, load_model
from monitor.sampling.read import read_recording

Progress = Callable[[str], None]


def _ours(model_path: Path, log: Path, out: Path) -> tuple[float, dict[str, float], dict]:
    cfg = load_config()
    t0 = time.perf_counter()
    model = load_model(model_path)
    model.dgrnn.grnn.cutoff_index()  # built at load, as the CLI's first prediction does
    t1 = time.perf_counter()
    rec = read_recording(log)
    t2 = time.perf_counter()
    det = detect(model, rec, cfg.alarm, horizon=1)
    t3 = time.perf_counter()
    with out.open("w", encoding="utf-8") as fh:
        fh.writelines(json.dumps(e) + "\n" for e in det.events)
    t4 = time.perf_counter()
    parts = {
        "load_model_s": t1 - t0,
        "read_log_s": t2 - t1,
        "detect_s": t3 - t2,
        "write_s": t4 - t3,
    }
    return t4 - t0, parts, det.summary


def reference_pipeline(model: MonitorModel, log: Path, dbc: Path) -> dict[str, Any]:
    """python-can + cantools + pyGRNN over ``log``; returns what it found, for a check."""
    spec = model.spec
    names = list(spec.variables)
    Z = model.normalizer.transform(_reference_rows(log, dbc, names), names)
    y = _reference_predict(model, Z)
    nout = len(spec.outputs)
    e = y - Z[:, :nout]
    if model.residual_clip is not None:
        e = np.clip(e, -np.asarray(model.residual_clip), np.asarray(model.residual_clip))
    s = np.mean(e * e, axis=1)
    win = model.window_n + 1
    csum = np.concatenate([[0.0], np.cumsum(np.nan_to_num(s))])
    j = np.full(len(s), np.nan)
    j[win - 1 :] = (csum[win:] - csum[:-win]) / win
    above = np.nan_to_num(j) > model.eps0
    run = max((sum(1 for _ in grp) for v, grp in itertools.groupby(above) if v), default=0)
    max_j = float(np.nanmax(j)) if np.isfinite(j).any() else None
    return {"samples": len(Z), "y_hat_z": y, "alarm": run >= 50, "max_J": max_j}


def _reference_rows(log: Path, dbc: Path, names: list[str]) -> np.ndarray:
    """The latest decoded value of each signal on the 10 ms grid, (rows, names)."""
    db = cantools.database.load_file(str(dbc))
    if not isinstance(db, cantools.database.can.Database):
        raise TypeError(f"{dbc}: not a CAN database")
    latest = dict.fromkeys(names, np.nan)
    rows, t0, k = [], None, 0
    with can.LogReader(str(log)) as reader:
        for msg in reader:
            try:
                # Casts: cantools decodes any bytes-like (its annotation says bytes) and, with
                # containers not decoded (the default), gives a mapping of this DBC's numbers
                # (its annotation is the union of every kind of result).
                values = cast(
                    Mapping[str, float],
                    db.decode_message(msg.arbitration_id, cast(bytes, msg.data)),
                )
            except KeyError:
                continue
            if t0 is None:
                t0 = msg.timestamp
            while t0 + k * 0.01 < msg.timestamp - 1e-6:  # rows before this frame
                rows.append([latest[n] for n in names])
                k += 1
            for n in names:
                if n in values:
                    latest[n] = float(values[n])
    rows.append([latest[n] for n in names])
    return np.array(rows)


def _reference_predict(model: MonitorModel, Z: np.ndarray) -> np.ndarray:
    """pyGRNN's prediction of each output (z-units) from the lag embedding of ``Z``, with
    the model's patterns and sigma; NaN where a lag is missing."""
    from pyGRNN import GRNN as PyGRNN

    spec = model.spec
    fvar, flag = spec.feature_columns()
    L = spec.max_lag
    X = np.column_stack([Z[L - lag : len(Z) - lag, v] for v, lag in zip(fvar, flag, strict=True)])
    ok = np.isfinite(X).all(axis=1)
    g = model.dgrnn.grnn
    nout = len(spec.outputs)
    y = np.full((len(Z), nout), np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for o in range(nout):
            ref = PyGRNN(kernel="RBF", sigma=g.sigma_, calibration="None")
            ref.fit(g.patterns_, g.targets_[:, o])
            Xo = X[ok]
            pred = np.concatenate([ref.predict(Xo[i : i + 1000]) for i in range(0, len(Xo), 1000)])
            col = np.full(len(X), np.nan)
            col[ok] = pred
            y[L:, o] = col
    delta = spec.delta_mask().astype(bool)
    y[1:, delta] += Z[:-1, :nout][:, delta]
    return y


def _slice(log: Path, seconds: float, out: Path) -> int:
    """The first ``seconds`` of ``log`` into ``out``; returns its frame count."""
    n = 0
    with log.open() as src, out.open("w") as dst:
        first = None
        for line in src:
            ts = float(line[1 : line.index(")")])
            first = ts if first is None else first
            if ts - first > seconds:
                break
            dst.write(line)
            n += 1
    return n


def measure(
    model_path: Path,
    log: Path,
    duration_s: float,
    reference_s: float,
    say: Progress,
    repeats: int = 3,
) -> dict[str, Any]:
    tmp = Path(tempfile.mkdtemp(prefix="monitor-bench-detect-"))
    with log.open("rb") as fh:
        frames = sum(1 for _ in fh)
    say(f"detect: {frames} frames, {duration_s:.0f} s of log; warm-up run")
    total, parts, summary = _ours_median(model_path, log, tmp, repeats)
    say(f"  ours: {total:.2f} s median of {repeats} ({duration_s / total:.0f}x real time)")
    no_isolation_s = _without_isolation_s(model_path, log)
    cli_s = _cli_cold_s(model_path, log, tmp)
    ref = _against_reference(model_path, log, reference_s, tmp, say)
    per_frame_ours = total / frames
    per_frame_ref = ref["reference_s"] / ref["reference_frames"]
    say(f"  reference {per_frame_ref * 1e6:.1f} us/frame vs ours {per_frame_ours * 1e6:.2f}")
    return {
        "log_frames": frames,
        "log_s": duration_s,
        "detect_s": total,
        "detect_parts_s": parts,
        "detect_s_without_isolation": no_isolation_s,
        "fault_s_in_log": duration_s - summary["first_alarm_t"] if summary["alarm"] else 0.0,
        "detect_frames_per_s": frames / total,
        "detect_realtime_factor": duration_s / total,
        "detect_cli_cold_wall_s": cli_s,
        "alarm": summary["alarm"],
        "first_alarm_t": summary["first_alarm_t"],
        "reference_slice_s": reference_s,
        "reference_frames": ref["reference_frames"],
        "reference_s": ref["reference_s"],
        "reference_us_per_frame": per_frame_ref * 1e6,
        "reference_realtime_factor": reference_s / ref["reference_s"],
        "ours_on_slice_s": ref["ours_on_slice_s"],
        "ours_us_per_frame": per_frame_ours * 1e6,
        "detect_speedup_vs_reference_pipeline": per_frame_ref / per_frame_ours,
        "reference_max_abs_diff_z": ref["reference_max_abs_diff_z"],
    }


def _ours_median(
    model_path: Path, log: Path, tmp: Path, repeats: int
) -> tuple[float, dict[str, float], dict]:
    """Ours after a warm-up run: the median total and parts of ``repeats`` runs, and the
    summary of the last."""
    _ours(model_path, log, tmp / "events.jsonl")
    runs = []
    for _ in range(repeats):
        total, parts, summary = _ours(model_path, log, tmp / "events.jsonl")
        runs.append((total, parts))
    total = float(np.median([r[0] for r in runs]))
    parts = {k: float(np.median([r[1][k] for r in runs])) for k in runs[0][1]}
    return total, parts, summary


def _without_isolation_s(model_path: Path, log: Path) -> float:
    """What fault isolation costs: it runs per sample while in fault (numpy cosine
    similarity); the detect part's time without it."""
    plain = dataclasses.replace(load_model(model_path), isolation=Isolation())
    rec = read_recording(log)
    t0 = time.perf_counter()
    detect(plain, rec, load_config().alarm, horizon=1)
    return time.perf_counter() - t0


def _cli_cold_s(model_path: Path, log: Path, tmp: Path) -> float:
    """Wall time of `monitor detect` in a new process, imports included."""
    cli_start = time.perf_counter()
    subprocess.run(
        [
            sys.executable,
            "-m",
            "monitor",
            "detect",
            str(log),
            "--model",
            str(model_path),
            "--horizon",
            "1",
            "--j-every",
            "0",
            "--events",
            str(tmp / "cli.jsonl"),
        ],
        check=True,
        capture_output=True,
    )
    return time.perf_counter() - cli_start


def _against_reference(
    model_path: Path, log: Path, reference_s: float, tmp: Path, say: Progress
) -> dict[str, Any]:
    """The reference pipeline and ours on the first ``reference_s`` of ``log``: times,
    frames and how far apart the predictions are (z-units)."""
    piece = tmp / "slice.log"
    ref_frames = _slice(log, reference_s, piece)
    model = load_model(model_path)
    say(f"  reference pipeline on the first {reference_s:.0f} s ({ref_frames} frames)")
    t0 = time.perf_counter()
    ref = reference_pipeline(model, piece, load_config().dbc)
    ref_s = time.perf_counter() - t0
    ours_slice_s, _, _ = _ours(model_path, piece, tmp / "slice.jsonl")
    mine = detect(model, read_recording(piece), horizon=1)
    n = min(len(mine.y_hat), ref["samples"])
    outputs = list(model.spec.outputs)
    z_mine = model.normalizer.transform(mine.y_hat[:n], outputs)
    agree = np.nanmax(np.abs(z_mine - ref["y_hat_z"][:n]))
    return {
        "reference_frames": ref_frames,
        "reference_s": ref_s,
        "ours_on_slice_s": ours_slice_s,
        "reference_max_abs_diff_z": float(agree),
    }
