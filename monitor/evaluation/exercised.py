"""Which fault runs the duty cycle exercised: detection split by the fault's own J.

A run is *exercised* when its ``fault_j_ratio`` (``monitor.evaluation.twins``: the J of the
noise-free difference the fault made, over eps0) reached 1.  The plain detection rate stays
the goal's measure; these counts tell "the detector missed it" (exercised, not detected)
from "the duty cycle never moved the signals that far" (not exercised).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

#: fault_j_ratio at or above this: the fault alone moved J to the threshold.
EXERCISED_RATIO = 1.0


def exercised_cell(runs: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Counts for one cell of runs; empty when any run lacks its twins (``--no-twins``)."""
    if not runs or any(r.get("fault_j_ratio") is None for r in runs):
        return {}
    hit = [r for r in runs if r["fault_j_ratio"] >= EXERCISED_RATIO]
    rest = [r for r in runs if r["fault_j_ratio"] < EXERCISED_RATIO]
    hit_det = sum(bool(r["detected"]) for r in hit)
    rest_det = sum(bool(r["detected"]) for r in rest)
    return {
        "exercised": len(hit),
        "detected_exercised": hit_det,
        "detection_rate_exercised": hit_det / len(hit) if hit else None,
        "detected_not_exercised": rest_det,
        "detection_rate_not_exercised": rest_det / len(rest) if rest else None,
    }


def _rate(detected: int, runs: int) -> str:
    return "-" if runs == 0 else f"{detected}/{runs}"


def exercised_markdown(per_severity: Sequence[dict[str, Any]]) -> list[str]:
    """The table per fault and severity (onsets pooled), or nothing without twins."""
    rows = [r for r in per_severity if r["all"].get("exercised") is not None]
    if not rows:
        return []
    out = [
        "",
        "Could a detector see it (noise-free twin runs; exercised = the fault's own J reached "
        "eps0; onsets pooled):",
        "",
        "| fault | severity | runs | detected | exercised | detected, exercised | "
        "detected, not exercised |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for row in rows:
        c = row["all"]
        n = c["runs"]
        out.append(
            f"| {row['fault']} | {row['severity']:g} | {n} | {_rate(c['detected'], n)} | "
            f"{c['exercised']} | {_rate(c['detected_exercised'], c['exercised'])} | "
            f"{_rate(c['detected_not_exercised'], n - c['exercised'])} |"
        )
    return out
