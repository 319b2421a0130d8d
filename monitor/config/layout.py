"""The daemon's sampler row for the configured loops, checked against the DBC; a loop's model
checked against the loop (``check_loop_model``).

The daemon's sampler makes one 100 Hz row whose columns are DBC signal names: every signal
any loop reads (``PP`` for the boom, ``Stick_PP`` for the stick, ``EngineSpeed`` shared...).
A loop sees that same row through its *view*: the row's column names with the loop's own
signals under their contract names and every other column under a name no model uses
(``OTHER`` first), so the ticker, the gating and the diagnostics work unchanged on it, and a
row is decoded and sampled once whatever the number of loops.  The other loops' spool
commands are the exception: they are named ``SpoolCmd@LOOP`` (``neighbour``), so that a
loop on a pump it shares can take its neighbours' demand as inputs of its model, the same
columns in training, ``monitor detect --loop`` and the daemon.  With one loop and the
contract names the row is exactly ``monitor.sampling.sampler.ROW_COLUMNS``.  The daemon
(``monitor.live``) and the offline readers (``monitor.offline``) both lay rows out here.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

from monitor.codec.frames import FrameCodec
from monitor.config.loops import LoopConfig
from monitor.config.settings import MonitorConfig
from monitor.errors import ConfigError
from monitor.model.machinecard import check_model_for_loop
from monitor.model.modelfile import MonitorModel
from monitor.sampling.sampler import ROW_COLUMNS
from monitor.signals import ROD_POS, neighbour

OTHER = "~"  # prefix of a column that belongs to another loop (no model signal starts so)
#: The contract signals of another loop its neighbours see (``neighbour``): its demand.
SHARED_WITH_NEIGHBOURS = ("SpoolCmd",)


_ALARM_SIGNALS = ("State", "Fault", "J", "Threshold", "AlarmCount")


def row_layout(
    cfg: MonitorConfig, codec: FrameCodec
) -> tuple[tuple[str, ...], list[tuple[str, ...]]]:
    """(row columns, one view per loop) for ``cfg.monitored_loops`` on ``codec``'s DBC.

    A signal a loop names must be in the DBC, and so must every contract signal it reads
    under its own name except the optional RodPos; its alarm message must have MON_Alarm's
    signals.  Anything else is a ``ConfigError`` naming the config key and the DBC."""
    loops = cfg.monitored_loops
    known = {s for info in codec.messages.values() for s in info.signal_names}
    columns: list[str] = []
    for i, lp in enumerate(loops):
        where = f"{cfg.source}: loops[{i}]" if cfg.loops else f"{cfg.source}: dbc"
        for contract in ROW_COLUMNS:
            name = lp.dbc_signal(contract)
            if name is None:
                continue  # RodPos: null
            if name not in known and (contract in lp.signals or contract != ROD_POS.name):
                key = f".signals.{contract}" if contract in lp.signals else f" ({contract})"
                raise ConfigError(f"{where}{key}: no signal {name!r} in {cfg.dbc}")
            if name not in columns:
                columns.append(name)
        _check_alarm_message(lp.alarm_message, codec, where, cfg)
    views = [_view(lp, loops, columns) for lp in loops]
    return tuple(columns), views


def _check_alarm_message(name: str, codec: FrameCodec, where: str, cfg: MonitorConfig) -> None:
    info = codec.messages.get(name)
    if info is None:
        raise ConfigError(f"{where}.alarm_message: no message {name!r} in {cfg.dbc}")
    missing = [s for s in _ALARM_SIGNALS if s not in info.signal_names]
    if missing:
        raise ConfigError(
            f"{where}.alarm_message: {name} in {cfg.dbc} lacks MON_Alarm's "
            f"signal(s) {', '.join(missing)}"
        )


def _view(lp: LoopConfig, loops: Iterable[LoopConfig], columns: list[str]) -> tuple[str, ...]:
    theirs = {
        other.dbc_signal(c): neighbour(c, other.name)
        for other in loops
        if other.name != lp.name
        for c in SHARED_WITH_NEIGHBOURS
    }
    own = {lp.dbc_signal(c): c for c in ROW_COLUMNS}
    return tuple(own.get(name, theirs.get(name, OTHER + name)) for name in columns)


def rod_columns(loops: Iterable[LoopConfig]) -> set[str]:
    """The row columns of the loops' rod sensors: optional, they hold no row back while the
    sampler warms up (``Sampler(optional=...)``)."""
    return {s for lc in loops if (s := lc.dbc_signal(ROD_POS.name)) is not None}


def check_loop_model(
    model: MonitorModel, lc: LoopConfig, cfg: MonitorConfig, path: str | Path | None = None
) -> None:
    """Refuse ``model`` (from ``path``, default the loop's) for loop ``lc`` of ``cfg`` when
    it was trained on another loop or machine (``monitor.model.machinecard``)."""
    where = f"{cfg.source}: loops[{cfg.loops.index(lc)}]" if lc in cfg.loops else str(cfg.source)
    if lc.machine_source is not None:
        where += f" (machine {lc.machine_source.name})"
    check_model_for_loop(model.card, model.envelope, path or lc.model, lc.name, lc.machine, where)
