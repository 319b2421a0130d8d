"""Which fault runs the duty cycle exercised: detection split by the fault's own J.

A run is *exercised* when the fault alone, as the noise-free twin runs measure it
(``monitor.evaluation.twins``), moved J to eps0: ``fault_j_ratio`` >= 1.  The plain
detection rate stays the goal's measure; these counts tell "the detector missed it"
(exercised, not detected) from "the duty cycle never moved the signals that far in J" (not
exercised; the bias statistic B, a mean, may still find such a run).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

#: A fault ratio at or above this: the fault alone moved the statistic to its threshold.
EXERCISED_RATIO = 1.0
#: Run key -> the name of its counts in a cell and its report heading.  Exercised: the
#: fault's own J over the outputs' difference; passed: the alarm level (J or B) of the
#: change the fault makes in this model's residual (``--twin-residuals``).
MEASURES = (
    ("fault_j_ratio", "exercised"),
    ("fault_residual_level_ratio", "passed"),
)


def exercised_cell(runs: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Counts for one cell of runs, per measure every run has (none with ``--no-twins``)."""
    out: dict[str, Any] = {}
    for key, name in MEASURES:
        if not runs or any(r.get(key) is None for r in runs):
            continue
        hit = [r for r in runs if r[key] >= EXERCISED_RATIO]
        rest = [r for r in runs if r[key] < EXERCISED_RATIO]
        hit_det = sum(bool(r["detected"]) for r in hit)
        rest_det = sum(bool(r["detected"]) for r in rest)
        out[name] = len(hit)
        out[f"detected_{name}"] = hit_det
        out[f"detection_rate_{name}"] = hit_det / len(hit) if hit else None
        out[f"detected_not_{name}"] = rest_det
        out[f"detection_rate_not_{name}"] = rest_det / len(rest) if rest else None
    return out


def _of(detected: int, runs: int) -> str:
    return "-" if runs == 0 else f"{detected}/{runs}"


def exercised_markdown(per_severity: Sequence[dict[str, Any]]) -> list[str]:
    """The table per fault and severity (onsets pooled), or nothing without twins."""
    rows = [r for r in per_severity if r["all"].get("exercised") is not None]
    if not rows:
        return []
    names = [n for _, n in MEASURES if all(r["all"].get(n) is not None for r in rows)]
    head = "| fault | severity | detected |" + "".join(
        f" {n} | detected, {n} | detected, not {n} |" for n in names
    )
    out = [
        "",
        "Could a detector see it (noise-free twin runs, onsets pooled). Exercised: the fault's "
        "own J (noise-free faulty minus healthy outputs, z-scored as the model does) reached "
        "eps0. Passed (--twin-residuals): the change the fault made in this model's residual "
        "reached the alarm level (J or B). Detected x/y: x of the y runs of that column.",
        "",
        head,
        "|---|---:|---:|" + "---:|---:|---:|" * len(names),
    ]
    for row in rows:
        c = row["all"]
        n = c["runs"]
        cells = [_of(c["detected"], n)]
        for name in names:
            k = c[name]
            cells += [str(k), _of(c[f"detected_{name}"], k), _of(c[f"detected_not_{name}"], n - k)]
        out.append(f"| {row['fault']} | {row['severity']:g} | " + " | ".join(cells) + " |")
    return out
