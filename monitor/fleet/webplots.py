"""The fleet page's interactive plots (plotly; its JavaScript ships beside the pages as
plotly.min.js, so they work from disk without a network connection)."""

from __future__ import annotations

from typing import Any

import numpy as np

from monitor.fleet.health import health_index

_VERDICT_COLOURS = {
    "fault": "#d62728",
    "sensor_fault": "#ff7f0e",
    "healthy": "#2ca02c",
    "not_judged": "#999999",
}
#: Seconds shown before and after an alarm episode in the signal plot.
AROUND_S = 20.0
#: Samples drawn per signal at most (a minute at 100 Hz; an episode of hours is thinned:
#: the page stays a few MB, and the plot's zoom shows the shape, not single samples).
MAX_POINTS = 6000


def _div(fig: Any, div_id: str) -> str:
    fig.update_layout(margin={"l": 60, "r": 20, "t": 50, "b": 50}, template="plotly_white")
    return fig.to_html(
        full_html=False,
        include_plotlyjs=False,
        div_id=div_id,
        config={"displaylogo": False, "responsive": True},
    )


def health_plot(rows: list[dict[str, Any]], names: list[str], warning_log: int | None) -> str:
    """One machine's health index per log (markers coloured by verdict), the median
    J / eps0, the alarm threshold 1.0 and the first warning."""
    import plotly.graph_objects as go

    x = names
    index = [health_index(r) for r in rows]
    fig = go.Figure()
    fig.add_trace(
        go.Scatter(
            x=x,
            y=index,
            mode="lines+markers",
            name="health index (largest alarm level)",
            line={"color": "#1f77b4"},
            marker={
                "size": 10,
                "color": [_VERDICT_COLOURS.get(r["verdict"], "#333") for r in rows],
            },
            text=[r["verdict"] for r in rows],
            hovertemplate="%{x}: %{y:.2f} (%{text})<extra></extra>",
        )
    )
    fig.add_trace(
        go.Scatter(
            x=x,
            y=[r.get("p50_j_ratio") for r in rows],
            mode="lines",
            name="median J / eps0",
            line={"dash": "dot", "color": "#7f7f7f"},
        )
    )
    fig.add_hline(
        y=1.0, line={"color": "#d62728", "width": 1}, annotation_text="alarm threshold (1.0)"
    )
    if warning_log is not None:
        fig.add_vline(
            x=warning_log - 1,
            line={"color": "#9467bd", "dash": "dot"},
            annotation_text="first warning",
        )
    top = max([v for v in index if v is not None] + [1.0])
    fig.update_layout(
        title="Health index per log (1.0 = alarm; marker colour = verdict: red "
        "fault, orange sensor fault, green healthy, grey not judged)",
        title_font_size=13,
        height=380,
        yaxis_title="level (1.0 = alarm)",
        xaxis_title="log (time order)",
        yaxis_range=[0, 1.1 * max(top, 1.3)],
        legend={"orientation": "h", "y": -0.3},
    )
    return _div(fig, "health")


def fleet_plot(views: list[Any]) -> str:
    """Every machine's (a whole machine's: every loop's) health index per log on one plot
    (click a legend entry to hide)."""
    import plotly.graph_objects as go

    fig = go.Figure()
    for v in sorted(views, key=lambda v: v.machine):  # stable: a machine's loops in order
        fig.add_trace(
            go.Scatter(
                x=list(range(1, len(v.rows) + 1)),
                y=[health_index(r) for r in v.rows],
                mode="lines+markers",
                name=v.name,
                text=[r["log"] for r in v.rows],
                hovertemplate="%{text}: %{y:.2f}<extra></extra>",
            )
        )
    n = max((len(v.rows) for v in views), default=1)
    # The threshold as a legend entry (an hline's label is misplaced on a log axis).
    fig.add_trace(
        go.Scatter(
            x=[1, n],
            y=[1.0, 1.0],
            mode="lines",
            name="alarm threshold (1.0)",
            line={"color": "#d62728", "width": 1},
            hoverinfo="skip",
        )
    )
    fig.update_layout(
        title="Health index of every machine per log (1.0 = alarm)",
        title_font_size=13,
        height=360,
        xaxis_title="log number (time order)",
        yaxis_title="level (1.0 = alarm)",
    )
    top = max((health_index(r) or 0.0 for v in views for r in v.rows), default=0.0)
    if top > 5:  # one machine far above the rest would flatten them: a log scale
        fig.update_yaxes(type="log")
    if n <= 30:
        fig.update_xaxes(tickmode="linear", dtick=1)  # whole log numbers only
    return _div(fig, "fleet-health")


def _window(t: np.ndarray, start: float, end: float) -> slice:
    lo = int(np.searchsorted(t, start - AROUND_S))
    hi = max(int(np.searchsorted(t, end + AROUND_S)), lo + 1)
    return slice(lo, hi, -(-(hi - lo) // MAX_POINTS))  # every k-th sample, k >= 1


def signal_plot(trace: dict[str, Any], alarm: Any, div_id: str) -> str:
    """The signals and statistics of one log around one alarm episode: pressures (bar),
    flow (L/min) and spool command (%), and J / eps0 with the alarm level (1.0 = alarm);
    the episode shaded."""
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    t = np.asarray(trace["t"], float)
    w = _window(t, alarm.span.start_t, alarm.span.end_t)
    tw = t[w]

    def y(x: np.ndarray) -> np.ndarray:  # float32: 7 digits are plenty on a plot
        return np.asarray(x[w], np.float32)

    fig = make_subplots(
        rows=3,
        cols=1,
        shared_xaxes=True,
        vertical_spacing=0.06,
        subplot_titles=(
            "pressures [bar]",
            "flow QP [L/min], spool command [%]",
            "statistics (1.0 = alarm)",
        ),
    )
    sig = trace["signals"]
    for name in ("PP", "PA", "PB"):
        if name in sig:
            fig.add_trace(go.Scatter(x=tw, y=y(sig[name]), name=f"{name} [bar]"), row=1, col=1)
    for name, unit in (("QP", "L/min"), ("SpoolCmd", "%")):
        if name in sig:
            fig.add_trace(go.Scatter(x=tw, y=y(sig[name]), name=f"{name} [{unit}]"), row=2, col=1)
    stat = trace.get("stat_name", "J / eps0")  # the pump's: its margin residual
    fig.add_trace(go.Scatter(x=tw, y=y(trace["j_ratio"]), name=stat), row=3, col=1)
    if trace.get("level") is not None:
        fig.add_trace(
            go.Scatter(x=tw, y=y(trace["level"]), name="alarm level", line={"dash": "dot"}),
            row=3,
            col=1,
        )
    fig.add_hline(y=1.0, line={"color": "#d62728", "width": 1}, row=3, col=1)
    colour = "#d62728" if alarm.kind == "fault" else "#ff7f0e"
    for r in (1, 2, 3):
        fig.add_vrect(
            x0=alarm.span.start_t,
            x1=alarm.span.end_t,
            fillcolor=colour,
            opacity=0.12,
            line_width=0,
            row=r,
            col=1,
        )
    fig.update_xaxes(title_text="time in the log [s]", row=3, col=1)
    fig.update_layout(
        height=620,
        title=f"{alarm.log}: {alarm.what} from {alarm.span.start_t:.1f} s "
        f"to {alarm.span.end_t:.1f} s (shaded)",
        title_font_size=13,
    )
    return _div(fig, div_id)
