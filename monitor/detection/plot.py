"""The picture of a detection run: signals and predictions, residuals, each statistic over
its threshold."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from monitor.detection.alarm import State
from monitor.detection.offline import Detection
from monitor.io.recording import Recording
from monitor.model.statistic import registry
from monitor.signals import UNITS

_STATE_COLOURS = {State.FAULT: "tab:red", State.SENSOR_FAULT: "tab:orange", State.INACTIVE: "0.8"}


def plot_detection(rec: Recording, det: Detection, outputs: tuple[str, ...], path: Path) -> None:
    """Measured and predicted outputs, residuals, and each statistic over its threshold."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = det.t - det.t[0]
    n_sig = len(outputs)
    fig, axes = plt.subplots(n_sig + 2, 1, figsize=(12, 2.0 * (n_sig + 2) + 1), sharex=True)
    _outputs(axes[:n_sig], t, rec, det, outputs)
    _residuals(axes[n_sig], t, det, outputs)
    _levels(axes[-1], t, det)
    _states(axes, t, det)
    _out_of_range(axes[-1], t, det)
    fig.suptitle(_title(det.summary), fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _outputs(
    axes: Any, t: np.ndarray, rec: Recording, det: Detection, outputs: tuple[str, ...]
) -> None:
    """One panel per model output: measured and predicted."""
    for ax, name, k in zip(axes, outputs, range(len(outputs)), strict=True):
        ax.plot(t, rec[name], lw=0.6, color="0.2", label=f"{name} measured")
        ax.plot(t, det.y_hat[:, k], lw=0.6, color="tab:blue", alpha=0.8, label="DGRNN")
        ax.set_ylabel(f"{name} [{UNITS[name]}]")
        ax.legend(loc="upper right", fontsize=7)


def _residuals(ax: Any, t: np.ndarray, det: Detection, outputs: tuple[str, ...]) -> None:
    for k, name in enumerate(outputs):
        ax.plot(t, det.residual[:, k], lw=0.5, label=name)
    ax.set_ylabel("residual e [z]")
    ax.legend(loc="upper right", fontsize=7, ncol=len(outputs))


def _states(axes: Any, t: np.ndarray, det: Detection) -> None:
    """Fault, sensor fault and inactive shaded on every panel."""
    for state, colour in _STATE_COLOURS.items():
        mask = det.state == state
        if mask.any():
            for ax in axes:
                ax.fill_between(
                    t,
                    0,
                    1,
                    where=mask,
                    transform=ax.get_xaxis_transform(),
                    color=colour,
                    alpha=0.15,
                    lw=0,
                )


def _out_of_range(ax: Any, t: np.ndarray, det: Detection) -> None:
    """Outside the training envelope: not judged (hatched, so it reads over a state colour)."""
    if det.gates is None or not np.any(det.gates.oor >= 0):
        return
    ax.fill_between(
        t,
        0,
        1,
        where=det.gates.oor >= 0,
        transform=ax.get_xaxis_transform(),
        facecolor="none",
        edgecolor="tab:purple",
        hatch="//",
        lw=0,
        label="out of range",
    )
    ax.legend(loc="upper left", fontsize=7)


def _title(s: dict[str, Any]) -> str:
    verdict = (
        f"FAULT at {s['first_alarm_t']:.1f} s ({s['fault']})"
        if s["alarm"]
        else "no hydraulic fault"
    )
    top = "n/a" if s.get("max_level") is None else f"{s['max_level']:.3g}"
    return f"{Path(str(s['source'])).name}: {verdict}; max level {top} (1 = alarm)"


def _levels(ax: Any, t: np.ndarray, det: Detection) -> None:
    """Every statistic of the family over its own threshold: the alarm is raised when one
    stays above 1 (the largest ratio is the level the alarm machine sees)."""
    entries = det.summary.get("statistics", {})
    for stat in registry():
        values, threshold = det.series.get(stat.name), entries.get(stat.name, {}).get("threshold")
        if values is None or not threshold:  # none, or a threshold that never alarms
            continue
        v = np.where(values > 0, values, np.nan)
        name, thr = stat.name, stat.threshold_key
        ax.semilogy(
            t,
            v / threshold,
            lw=0.8,
            color=stat.colour,
            label=f"{name} / {thr} ({thr} = {threshold:.3g}{stat.unit})",
        )
    ax.axhline(1.0, color="tab:red", ls="--", lw=1, label="alarm threshold")
    ax.set_ylabel("level (1 = alarm)")
    ax.set_ylim(bottom=1e-2)  # below a hundredth of the threshold nothing is close
    ax.set_xlabel("time from first sample [s]")
    ax.legend(loc="upper left", fontsize=7)
