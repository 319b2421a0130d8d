"""`monitor fleet report`: the fleet page (Markdown) with its pictures (PNG).

A service manager's minute: the fleet table (last verdict, health index and its trend, the
predicted crossing, whether the page warned before the first alarm, sensor faults), the
health index over time per machine with eps0 (1.0) drawn, and the verdict timeline (alarm,
sensor fault, healthy, not judged, error per log).
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import Any

import pyarrow.parquet as pq

from monitor.errors import InputFileError
from monitor.fleet.health import (
    DRIFT_FLAG,
    DRIFT_LOGS,
    TREND_P,
    FirstWarning,
    Prognosis,
    drift,
    first_warning,
    health_index,
    prognosis,
)
from monitor.fleet.loops import has_loops, loop_order, machine_verdict, series_name, split
from monitor.fleet.pipeline import statistics, threshold_note
from monitor.fleet.store import on_off_text, trained_statistics

_COLOURS = {
    "fault": "tab:red",
    "sensor_fault": "tab:orange",
    "healthy": "tab:green",
    "not_judged": "0.6",
}


def load_rows(results: Path) -> dict[str, list[dict[str, Any]]]:
    """logs.parquet rows per machine, each machine's in time (file-name) order."""
    path = results / "logs.parquet"
    if not path.is_file():
        raise InputFileError(f"{path}: no such file (run `monitor fleet run` first)")
    table = pq.read_table(path).to_pylist()
    if not table:
        raise InputFileError(
            f"{path}: no rows yet (a first run stopped before its end?): "
            "run `monitor fleet run` again"
        )
    per: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for r in sorted(table, key=lambda r: r["log"]):
        per[r["machine"]].append(r)
    return dict(per)


def _pyplot():  # noqa: ANN202 - matplotlib.pyplot, imported lazily
    """pyplot on the file-only Agg backend (the report runs without a display)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _fmt(x: float | None) -> str:
    return "-" if x is None else f"{x:.2f}"


def _table(
    per: dict[str, list[dict[str, Any]]],
    progs: dict[str, Prognosis],
    warns: dict[str, FirstWarning],
    notes: dict[str, str],
) -> list[str]:
    out = [
        "| machine | logs | last verdict | health index (last max level) | drift from "
        "commissioning | trend per log | predicted crossing of 1.0 | first warning | alarms "
        "| sensor faults | errors | model |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for mid, rows in per.items():
        p = progs[mid]
        last = rows[-1]
        d = drift(rows)
        d_text = "-" if d is None else f"{d:.1f} x{' (wearing?)' if d >= DRIFT_FLAG else ''}"
        out.append(
            f"| {mid} | {len(rows)} | {last['verdict']} | {_fmt(p.last_index)} | {d_text} | "
            f"{'-' if p.slope_per_log is None else f'{p.slope_per_log:+.3f}'} | {p.text} | "
            f"{warns[mid].text} | {sum(bool(r['alarm']) for r in rows)} | "
            f"{sum(bool(r['sensor_fault']) for r in rows)} | "
            f"{sum(r['error'] is not None for r in rows)} | {last['model']}"
            f"{'; ' + notes[mid] if mid in notes else ''} |"
        )
    return out


def _trend_line(rows: list[dict[str, Any]], p: Prognosis, k: int):
    """x and level of the prognosis's line: over its fitted logs, then on to 1.0."""
    if p.logs_to_alarm is None or p.slope_per_log is None or p.level_now is None:
        return None
    pos = [i + 1 for i, r in enumerate(rows) if health_index(r) is not None and not r["error"]]
    pos = pos[-k:]
    ahead = max(min(p.logs_to_alarm, k), 0.0)  # no further than the fit reaches back
    x = [pos[0], pos[-1], pos[-1] + ahead]
    start = p.level_now - p.slope_per_log * (len(pos) - 1)
    return x, [start, p.level_now, p.level_now + p.slope_per_log * ahead]


def _ratios() -> str:
    """The statistics' ratios the alarm level is the largest of: "J / eps0, B / b0, ..."."""
    return ", ".join(f"{name} / {threshold}" for name, threshold, _ in statistics())


def _health_png(
    per: dict[str, list[dict[str, Any]]],
    progs: dict[str, Prognosis],
    warns: dict[str, FirstWarning],
    path: Path,
    k: int,
) -> None:
    plt = _pyplot()
    from matplotlib.ticker import MaxNLocator

    n = len(per)
    cols = min(3, n)
    nrows = (n + cols - 1) // cols
    # Own y scale per machine (a machine far above 1.0 would flatten the others), never
    # below 1.3 so that the alarm line is always in view.
    fig, axes = plt.subplots(nrows, cols, figsize=(4.2 * cols, 2.8 * nrows), squeeze=False)
    for ax, (mid, rows) in zip(axes.flat, per.items(), strict=False):
        x = list(range(1, len(rows) + 1))
        index = [health_index(r) for r in rows]
        ax.plot(x, index, "o-", label="health index (max level)")
        if any(r.get("max_level") not in (None, r["max_j_ratio"]) for r in rows):
            for name, threshold, column in statistics():  # which one set the index, by log
                peaks = [r.get(column) for r in rows]
                if any(v is not None for v in peaks):
                    ax.plot(x, peaks, ".:", label=f"max {name}/{threshold}")
        ax.plot(x, [r.get("p50_j_ratio") for r in rows], "s--", ms=3, label="median J/eps0")
        right = len(rows) + 0.5
        line = _trend_line(rows, progs[mid], k)
        if line is not None:
            ax.plot(*line, "-", color="tab:purple", lw=2, alpha=0.7, label="trend to 1.0")
            right = max(right, line[0][-1] + 0.5)
        ax.axhline(1.0, color="tab:red", lw=1, label="eps0 (alarm)")
        w = warns[mid].warning_log
        if w is not None:
            ax.axvline(w, color="tab:purple", ls=":", lw=1.5, label="first warning")
        ax.set_title(mid)
        ax.set_xlim(0.5, right)
        top = max([v for v in index if v is not None] + [1.0])
        ax.set_ylim(0.0, max(1.3, 1.08 * top))
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_xlabel("log (time order)")
        ax.grid(alpha=0.3)
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    axes[0][0].set_ylabel("level (1.0 = alarm)")
    handles, labels = axes[0][0].get_legend_handles_labels()
    if any(w.warning_log is not None for w in warns.values()) and "first warning" not in labels:
        # The legend sits on the first machine, which may not have warned itself.
        handles.append(
            plt.Line2D([], [], color="tab:purple", ls=":", lw=1.5, label="first warning")
        )
    axes[0][0].legend(handles=handles, fontsize=7)
    fig.suptitle("Health index per machine (1.0 = alarm threshold)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _drift_png(per: dict[str, list[dict[str, Any]]], path: Path) -> bool:
    """Each machine's drift per log (log scale) with the flag's mark; False when no row has a
    drift (results from before it), and then no picture."""
    series = {mid: [r.get("p50_j_drift") for r in rows] for mid, rows in per.items()}
    series = {mid: v for mid, v in series.items() if any(x is not None for x in v)}
    if not series:
        return False
    plt = _pyplot()
    from matplotlib.ticker import MaxNLocator, ScalarFormatter

    fig, ax = plt.subplots(figsize=(8, 4))
    for mid, v in series.items():
        ax.plot(
            range(1, len(v) + 1),
            [float("nan") if x is None else x for x in v],
            "o-",
            ms=3,
            label=mid,
        )
    ax.axhline(DRIFT_FLAG, color="tab:red", lw=1, ls="--", label=f"{DRIFT_FLAG:g} x: wearing?")
    ax.axhline(1.0, color="0.4", lw=1)
    ax.set_yscale("log")
    ax.yaxis.set_major_formatter(ScalarFormatter())
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("log (time order)")
    ax.set_ylabel("median J / commissioning's")
    ax.set_title("Drift from commissioning (1 = as commissioned)")
    ax.grid(alpha=0.3, which="both")
    if len(series) <= 12:
        ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return True


def _timeline_png(per: dict[str, list[dict[str, Any]]], path: Path) -> None:
    plt = _pyplot()
    from matplotlib.ticker import MaxNLocator

    fig, ax = plt.subplots(figsize=(8, 0.5 * len(per) + 1.8))
    for i, (_mid, rows) in enumerate(per.items()):
        for j, r in enumerate(rows, start=1):
            if r["error"] is not None:
                ax.plot(j, i, "kx", ms=9)
                continue
            ax.plot(j, i, "s", ms=12, color=_COLOURS.get(r["verdict"], "0.3"))
            if r["alarm"] and r["sensor_fault"]:
                ax.plot(j, i, "o", ms=5, color="tab:orange")
    ax.set_yticks(range(len(per)), list(per))
    ax.set_xlim(0.5, max(len(r) for r in per.values()) + 0.5)
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.invert_yaxis()
    ax.set_xlabel("log (time order)")
    handles = [
        plt.Line2D([], [], marker="s", ls="", color=c, label=v) for v, c in _COLOURS.items()
    ] + [plt.Line2D([], [], marker="x", ls="", color="k", label="error")]
    ax.legend(handles=handles, ncol=5, fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.2))
    ax.set_title("Verdict per log (orange dot: sensor fault beside an alarm)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _statistics_section(stats: dict[str, dict[str, str] | None]) -> list[str]:
    """Per commissioned machine, every statistic that is off or thinly supported, and why
    (the support rule's line, as `monitor train` said it)."""
    lines = [
        f"- {mid}: {name} {why}"
        for mid, known in stats.items()
        for name, why in (known or {}).items()
        if why != "on"
    ]
    if not lines:
        return []
    head = "## Commissioning: statistics off or thinly supported, and why"
    return [head, "", *lines, ""]


def _series(
    per: dict[str, list[dict[str, Any]]],
) -> tuple[dict[str, list[dict[str, Any]]], dict[str, str]]:
    """Each machine's rows, or (whole machines) each machine's loop's, by the series'
    name (``M01 stick``); and each series' model file stem in RESULTS/models."""
    from monitor.fleet.commission import model_name

    series, files = {}, {}
    for mid, rows in per.items():
        for loop, part in split(rows).items():
            name = series_name(mid, loop)
            series[name], files[name] = part, model_name((mid, loop))
    return series, files


def _machines_section(per: dict[str, list[dict[str, Any]]]) -> list[str]:
    """Whole machines: per machine its verdict on its newest log, naming the loop, and a
    cell per loop; [] for a fleet of one-loop logs."""
    if not has_loops(per):
        return []
    verdicts = [machine_verdict(mid, rows) for mid, rows in per.items()]
    loops = loop_order({loop for v in verdicts for loop in v.cells})
    out = [
        "## Machines (each loop judged on the newest log)",
        "",
        "| machine | newest log | verdict | " + " | ".join(loops) + " |",
        "|---|---|---|" + "---|" * len(loops),
    ]
    for v in verdicts:
        cells = [v.cells.get(loop, "-").replace("_", " ") for loop in loops]
        out.append(f"| {v.machine} | {v.log} | {v.text} | " + " | ".join(cells) + " |")
    # Why a row of the newest log is not judged (the pump's rule off, or no commissioning).
    why = [f"- {v.machine} {loop}: not judged: {w}" for v in verdicts for loop, w in v.why.items()]
    return [
        *out,
        "",
        *(why + [""] if why else []),
        "A loop's verdict: fault, sensor fault, healthy, not judged (nothing its detector "
        "could judge), error, or uncommissioned (no model of this machine's loop: not "
        "judged, or judged with another machine's model and its alarms withheld; never "
        "healthy). The pump (with the config's `pump:`): its rule with the machine's own "
        "margin law. With several alarms the machine's finding names one: the pump when "
        "its rule is in fault, else the loop whose alarm came first. Each loop's history "
        "below is a row of its own (`M01 stick`, `M01 pump`).",
        "",
    ]


def _intro(per: dict[str, list[dict[str, Any]]], series: dict[str, list[dict[str, Any]]]) -> str:
    n_rows = sum(len(r) for r in series.values())
    if not has_loops(per):
        return f"{len(per)} machines, {n_rows} logs."
    logs = {r["log"] for rows in per.values() for r in rows}
    return f"{len(per)} whole machines, {len(logs)} logs, {n_rows} log loops."


def _model_notes(
    results: Path, files: dict[str, str]
) -> tuple[dict[str, str], dict[str, dict[str, str] | None]]:
    """Per series (its model file stem in ``files``), the note beside its model, and which
    statistics its commissioned model judges with (the reasons below the table)."""
    # A threshold resting on one commissioning event makes a machine less sensitive to
    # slow wear than its neighbours: the page says so beside its model.
    notes, stats = {}, {}
    for mid, stem in files.items():
        path = results / "models" / f"{stem}.model.npz"
        stats[mid] = got = trained_statistics(results, stem)
        said = [threshold_note(path) if path.is_file() else None]
        said.append(None if got is None else on_off_text(got))
        if any(said):
            notes[mid] = "; ".join(n for n in said if n)
    return notes, stats


def write_report(results: Path, out: Path, k: int = 6) -> Path:
    """Write ``out/fleet.md``, ``out/health.png``, ``out/timeline.png`` and, when the
    results have drifts, ``out/drift.png``; the page's path.  Whole machines' rows (a
    ``loop`` each): a machines table, and each machine's loop a series of its own."""
    machines = load_rows(results)
    per, files = _series(machines)
    progs = {mid: prognosis(mid, rows, k) for mid, rows in per.items()}
    warns = {mid: first_warning(mid, rows, k) for mid, rows in per.items()}
    notes, stats = _model_notes(results, files)
    out.mkdir(parents=True, exist_ok=True)
    _health_png(per, progs, warns, out / "health.png", k)
    _timeline_png(per, out / "timeline.png")
    drift_pic = (
        ["![drift from commissioning](drift.png)", ""] if _drift_png(per, out / "drift.png") else []
    )
    lines = [
        "# Fleet report",
        "",
        f"{_intro(machines, per)} Health index: "
        f"the largest alarm level of a log, max({_ratios()}) (1.0 raises the alarm); "
        f"trend: Theil-Sen over the last {k} judged logs of their typical level (median J /"
        " eps0, which follows wear, scaled by the machine's peak-to-median ratio; the peak "
        "itself scatters with each log's manoeuvres), counted when Kendall's tau makes a "
        f"rise unlikely to be scatter (one-sided p < {TREND_P:g}, so at least 4 logs); "
        "crossing: logs until the trend reaches 1.0 (90 % interval); drift from "
        f"commissioning: median J of the last {DRIFT_LOGS} logs over the commissioning "
        f"run's, whatever eps0 is ({DRIFT_FLAG:g} x and above: wearing?); first warning: "
        "the page replayed log by log, the first log, before any alarm, at which the "
        f"drift reached {DRIFT_FLAG:g} x (machines without a commissioning run: at which "
        "the prognosis forecast a crossing with a bounded interval; dotted line on the "
        "plot), and how many logs (days) later the first alarm came.",
        "",
        *_machines_section(machines),
        *_table(per, progs, warns, notes),
        "",
        "![health index](health.png)",
        "",
        *drift_pic,
        "![verdict timeline](timeline.png)",
        "",
        *_statistics_section(stats),
    ]
    errors = [r for rows in per.values() for r in rows if r["error"] is not None]
    if errors:
        lines += ["## Logs that could not be judged", ""]
        lines += [
            f"- `{r['log']}`{' (' + r['loop'] + ')' if r.get('loop') else ''}: {r['error']}"
            for r in errors
        ]
    page = out / "fleet.md"
    page.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return page
