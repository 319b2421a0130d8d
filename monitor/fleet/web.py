"""`monitor fleet report --html` and `monitor fleet serve`: the fleet web page.

Static files (index.html, alarms.html, machine-<id>.html and plotly.min.js beside them)
that open from disk or any web server without a network connection.  The signals around
an alarm are read from the log itself (FLEET/<log>) and judged again with the machine's
model from RESULTS/models, so the page needs ``fleet`` for them.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from monitor.fleet import templates
from monitor.fleet.acks import SHELVE_DAYS, ack_path, read_acks
from monitor.fleet.episodes import row_episodes
from monitor.fleet.fleetview import Alarm, MachineView, code_groups, fleet_views, log_name
from monitor.fleet.health import health_index
from monitor.fleet.loops import has_loops, loop_order, machine_verdict
from monitor.fleet.pumpjob import PUMP
from monitor.fleet.store import on_off_text, trained_statistics

#: Alarm episodes per machine whose signals are plotted: the first and the newest of each
#: fault or sensor, at most this many (each needs its log judged again).
MAX_SIGNAL_PLOTS = 4


def _fmt(x: float | None) -> str:
    return "-" if x is None else f"{x:.2f}"


def _env():  # noqa: ANN202 - jinja2.Environment, imported lazily
    import jinja2

    loader = jinja2.DictLoader(
        {
            "base": templates.BASE,
            "index": templates.INDEX,
            "machine": templates.MACHINE,
            "alarms": templates.ALARMS,
        }
    )
    env = jinja2.Environment(loader=loader, autoescape=True, undefined=jinja2.StrictUndefined)
    env.globals.update(
        fmt=_fmt, index=health_index, n_episodes=lambda r: len(row_episodes(r)), on_off=on_off_text
    )
    return env


def _picked(alarms: list[Alarm]) -> list[Alarm]:
    """The first and the newest episode of each finding, oldest first, at most
    ``MAX_SIGNAL_PLOTS``."""
    by: dict[tuple[str, str], list[Alarm]] = {}
    for a in alarms:
        by.setdefault((a.kind, a.name), []).append(a)
    out: list[Alarm] = []
    for same in by.values():
        out += [same[0]] + ([same[-1]] if len(same) > 1 else [])
    out.sort(key=lambda a: alarms.index(a))
    return out[:MAX_SIGNAL_PLOTS]


def _model(v: MachineView) -> str:
    """The view's model file stem in RESULTS/models (``M01``, ``M01.stick``)."""
    from monitor.fleet.commission import model_name

    return model_name((v.machine, v.loop))


@dataclass
class Site:
    """The fleet page of one results folder."""

    results: Path
    per: dict[str, list[dict[str, Any]]]
    fleet: Path | None = None  # FLEET, for the signals around alarms
    config: str | None = None
    k: int = 6
    views: list[MachineView] = field(init=False)

    def __post_init__(self) -> None:
        self.views = fleet_views(self.per, self.k)
        # Commissioned machines (loops): whether each statistic is on and why
        # (trained-from.json), by the view's name.
        self.stats = {
            v.name: s for v in self.views if (s := trained_statistics(self.results, _model(v)))
        }
        # Whole machines: each one's verdict naming the loop, with a cell per loop.
        self.machines = [machine_verdict(m, rows) for m, rows in self.per.items()]
        self.machines = self.machines if has_loops(self.per) else []
        self._env = _env()
        self._plots: dict[str, tuple[list[str], str]] = {}  # per machine, made once

    def view(self, page: str) -> MachineView | None:
        """The machine whose page is ``page`` (``machine-M01.html``), None for none."""
        return next((v for v in self.views if v.page == page), None)

    @property
    def subtitle(self) -> str:
        now = dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
        return f"results {self.results.resolve()}, page made {now}"

    def _render(self, name: str, **kw: Any) -> str:
        return self._env.get_template(name).render(subtitle=self.subtitle, **kw)

    def index_html(self) -> str:
        from monitor.fleet.webplots import fleet_plot

        groups, periods = code_groups(self.views)
        acks = read_acks(self.results)
        unacked = sum(a.id not in acks for v in self.views for a in v.alarms)
        errors = [r for v in self.views for r in v.rows if r.get("error")]
        # Rows judged before episodes were kept: their alarms are in no list below.
        older = sum(
            r.get("episodes") is None and bool(r["alarm"] or r["sensor_fault"])
            for v in self.views
            for r in v.rows
        )
        return self._render(
            "index",
            title="Fleet",
            plots=True,
            views=self.views,
            n_logs=sum(len(v.rows) for v in self.views),
            groups=groups,
            periods=periods,
            unacked=unacked,
            errors=errors,
            older=older,
            stats=self.stats,
            fleet_plot=fleet_plot(self.views),
            machines=self.machines,
            loops=loop_order({loop for m in self.machines for loop in m.cells}),
            pages={(v.machine, v.loop): v.page for v in self.views},
        )

    def alarms_html(self, live: bool) -> str:
        acks = read_acks(self.results)
        now = dt.datetime.now(dt.timezone.utc)
        every = [a for v in self.views for a in v.alarms]
        every.sort(key=lambda a: (a.period, a.log, a.span.start_t), reverse=True)  # newest first
        shelved = [a for a in every if a.id in acks and acks[a.id].shelved(now)]
        active = [a for a in every if a not in shelved]
        return self._render(
            "alarms",
            title="Alarm list",
            plots=False,
            alarms=active,
            shelved=shelved,
            acks=acks,
            live=live,
            shelve_days=SHELVE_DAYS,
            ack_file=str(ack_path(self.results)),
        )

    def machine_html(self, v: MachineView) -> str:
        from monitor.fleet.webplots import health_plot

        if v.page not in self._plots:
            self._plots[v.page] = self._signal_plots(v)
        plots, note = self._plots[v.page]
        return self._render(
            "machine",
            title=f"{v.name}",
            plots=True,
            v=v,
            stats=self.stats.get(v.name),
            acks=read_acks(self.results),
            signal_plots=plots,
            signals_note=note,
            health_plot=health_plot(v.rows, [log_name(r) for r in v.rows], v.warning.warning_log),
        )

    def _signal_plots(self, v: MachineView) -> tuple[list[str], str]:
        from monitor.fleet.pipeline import trace_log
        from monitor.fleet.pumpjob import trace_pump_log
        from monitor.fleet.webplots import signal_plot

        if not v.alarms:
            return [], "No alarm episodes."
        if self.fleet is None:
            return [], (
                "Give the fleet folder (--fleet FLEET) to see the signals and "
                "statistics around each alarm, read from the log itself."
            )
        pump = v.loop == PUMP  # the pump rule's model and trace
        model = self.results / "models" / f"{_model(v)}{'.json' if pump else '.model.npz'}"
        if not model.is_file():
            return [], f"{model}: no such model file (needed to judge the log again)."
        logs = {log_name(r): r["log"] for r in v.rows}
        traces: dict[str, dict[str, Any]] = {}
        out, missing = [], []
        for i, a in enumerate(_picked(v.alarms)):
            path = self.fleet / logs[a.log]
            if not path.is_file():
                missing.append(str(path))
                continue
            if a.log not in traces and pump:
                traces[a.log] = trace_pump_log(model.read_bytes(), str(path), self.config)
            elif a.log not in traces:
                traces[a.log] = trace_log(
                    model.read_bytes(), str(path), self.config, v.loop, v.machine
                )
            out.append(signal_plot(traces[a.log], a, f"signals-{i}"))
        return out, ("" if out else f"Logs not found: {', '.join(missing)}")

    def write(self, out: Path) -> Path:
        """Every page and plotly.min.js into ``out``; index.html's path."""
        from plotly.offline import get_plotlyjs

        out.mkdir(parents=True, exist_ok=True)
        (out / "plotly.min.js").write_text(get_plotlyjs(), encoding="utf-8")
        for v in self.views:
            (out / v.page).write_text(self.machine_html(v), encoding="utf-8")
        (out / "alarms.html").write_text(self.alarms_html(live=False), encoding="utf-8")
        index = out / "index.html"
        index.write_text(self.index_html(), encoding="utf-8")
        return index
