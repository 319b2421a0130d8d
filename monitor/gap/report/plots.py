"""Pictures of a diagnosis: traces in the worst window, residual by regime, residual spectra,
and the candidates' held-out gap reduction."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from monitor.gap.diagnose.records import Diagnosis
from monitor.gap.fit.score import normalised
from monitor.gap.judge.where import spectra
from monitor.signals import MEASURED_NAMES, UNITS

#: Seconds shown either side of the worst window.
MARGIN_S = 2.0


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_traces(diag: Diagnosis, report: dict, path: Path) -> None:
    plt = _plt()
    prep, traces = diag.parts.prep, diag.traces
    t = prep.t - prep.t[0]
    win = report["where"]["windows"][0] if report["where"]["windows"] else None
    lo, hi = (win["t_start"] - MARGIN_S, win["t_end"] + MARGIN_S) if win else (0.0, 10.0)
    sel = (t >= lo) & (t <= hi)
    fig, axes = plt.subplots(5, 1, figsize=(11, 11), sharex=True)
    for ax, name in zip(axes, MEASURED_NAMES, strict=False):
        ax.plot(t[sel], prep.meas[name][sel], lw=0.7, color="0.2", label="measured")
        ax.plot(t[sel], traces.nominal[name][sel], lw=1.0, color="tab:blue", label="nominal")
        if traces.corrected is not None:
            label = f"with {report['verdict']}" + (f" + {report['also']}" if report["also"] else "")
            ax.plot(t[sel], traces.corrected[name][sel], lw=1.0, color="tab:red", label=label)
        ax.set_ylabel(f"{name} [{UNITS[name]}]")
        ax.legend(loc="upper right", fontsize=7)
    axes[-1].plot(t[sel], prep.cmd["SpoolCmd"][sel], color="k", lw=0.8)
    axes[-1].set_ylabel("SpoolCmd [%]")
    axes[-1].set_xlabel("time from start [s]")
    for seg in diag.parts.segments:
        if lo <= t[seg.start] <= hi:
            for ax in axes:
                ax.axvline(t[seg.start], color="0.7", lw=0.5, ls=":")
    fig.suptitle(
        f"Worst window {lo + MARGIN_S:g}-{hi - MARGIN_S:g} s (dotted: segment starts from the "
        "measured state)"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_regimes(report: dict, path: Path) -> None:
    plt = _plt()
    rows = report["where"]["regimes"]
    fig, ax = plt.subplots(figsize=(10, 0.35 * len(rows) + 1.5))
    y = np.arange(len(rows))[::-1]
    ax.barh(y + 0.2, [r["share"] * 100 for r in rows], 0.4, label="share of squared residual")
    ax.barh(y - 0.2, [r["time_share"] * 100 for r in rows], 0.4, label="share of time", color="0.7")
    ax.set_yticks(y, [r["regime"] for r in rows], fontsize=8)
    ax.set_xlabel("%")
    ax.set_title("Residual of the calibrated nominal simulator by operating regime")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_spectra(diag: Diagnosis, path: Path) -> None:
    plt = _plt()
    prep, traces = diag.parts.prep, diag.traces
    f, p0 = spectra(normalised(prep, traces.nominal))
    p1 = spectra(normalised(prep, traces.corrected))[1] if traces.corrected else None
    fig, axes = plt.subplots(2, 2, figsize=(11, 7), sharex=True)
    for ax, (j, name) in zip(axes.flat, enumerate(MEASURED_NAMES), strict=True):
        ax.loglog(f[1:], p0[name][1:], color="tab:blue", label="nominal")
        if p1 is not None:
            ax.loglog(f[1:], p1[name][1:], color="tab:red", label="corrected")
        # White sensor noise: flat at 2 var / fs in the one-sided density.
        ax.axhline(
            2 * diag.tolerances.floor[j] / 100.0, color="0.5", ls="--", lw=0.8, label="sensor noise"
        )
        ax.set_title(f"{name} residual (normalised)")
        ax.set_ylabel("PSD [1/Hz]")
        ax.legend(fontsize=7)
    for ax in axes[-1]:
        ax.set_xlabel("frequency [Hz]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_ranking(report: dict, path: Path) -> None:
    plt = _plt()
    rows = report["ranking"] + report["pairs"]
    fig, ax = plt.subplots(figsize=(9, 0.35 * len(rows) + 1.5))
    y = np.arange(len(rows))[::-1]
    ax.barh(y, [100 * r["heldout_reduction"] for r in rows], color="tab:green")
    ax.set_yticks(y, [r["effect"] for r in rows], fontsize=8)
    ax.axvline(0, color="k", lw=0.6)
    ax.set_xlabel("held-out gap removed [%]")
    ax.set_title(f"Candidates (verdict: {report['verdict']})")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_plots(diag: Diagnosis, report: dict, directory: Path) -> list[Path]:
    paths = {
        "traces_worst_window.png": lambda p: plot_traces(diag, report, p),
        "residual_by_regime.png": lambda p: plot_regimes(report, p),
        "residual_spectra.png": lambda p: plot_spectra(diag, p),
        "candidates.png": lambda p: plot_ranking(report, p),
    }
    out = []
    for name, draw in paths.items():
        draw(directory / name)
        out.append(directory / name)
    return out
