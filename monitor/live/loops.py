"""Several loops in one daemon: one sampler row for all, each loop's view of it, one ``Loop``
per loop (model, ticker, MON_Alarm frames, J1939 diagnostics).

The daemon's sampler makes one 100 Hz row whose columns are DBC signal names: every signal
any loop reads (``PP`` for the boom, ``Stick_PP`` for the stick, ``EngineSpeed`` shared...).
A loop sees that same row through its *view*: the row's column names with the loop's own
signals under their contract names and every other column under a name no model uses, so
the ticker, the gating and the diagnostics work unchanged on it, and a row is decoded and
sampled once whatever the number of loops.  With one loop and the contract names the row is
exactly ``monitor.sampling.sampler.ROW_COLUMNS``.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import can
import numpy as np

from monitor.codec.frames import FrameCodec
from monitor.config.loops import LoopConfig
from monitor.config.settings import MonitorConfig
from monitor.detection.alarm import State
from monitor.detection.plausibility import finding
from monitor.detection.ticker import Tick, Ticker, event
from monitor.errors import ConfigError, InputFileError, NoHydraulicDataError
from monitor.io.recording import Recording
from monitor.live.dm1 import Diagnostics
from monitor.live.outputs import AlarmFrames
from monitor.model.machinecard import check_model_for_loop
from monitor.model.modelfile import MonitorModel, load_model
from monitor.sampling.bulk import recording_from_candump_bulk
from monitor.sampling.read import read_recording
from monitor.sampling.sampler import ROW_COLUMNS
from monitor.signals import ROD_POS

_OTHER = "~"  # prefix of a column that belongs to another loop (no model signal starts so)
_ALARM_SIGNALS = ("State", "Fault", "J", "Threshold", "AlarmCount")
# MON_Status shows the most pressing loop: a fault before a sensor fault before normal.
_SEVERITY = {State.FAULT: 3, State.SENSOR_FAULT: 2, State.NORMAL: 1, State.INACTIVE: 0}


def worst_state(states: Sequence[State]) -> State:
    return max(states, key=_SEVERITY.__getitem__)


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
    views = [_view(lp, columns) for lp in loops]
    return tuple(columns), views


def _check_alarm_message(name: str, codec: FrameCodec, where: str, cfg: MonitorConfig) -> None:
    info = codec.messages.get(name)
    if info is None:
        raise ConfigError(f"{where}.alarm_message: no message {name!r} in {cfg.dbc}")
    missing = [s for s in _ALARM_SIGNALS if s not in info.signal_names]
    if missing:
        raise ConfigError(f"{where}.alarm_message: {name} in {cfg.dbc} lacks MON_Alarm's "
                          f"signal(s) {', '.join(missing)}")  # fmt: skip


def _view(lp: LoopConfig, columns: list[str]) -> tuple[str, ...]:
    own = {lp.dbc_signal(c): c for c in ROW_COLUMNS}
    return tuple(own.get(name, _OTHER + name) for name in columns)


class Loop:
    """One monitored loop: its model and ticker on its view of the row, its MON_Alarm
    frames and (with J1939 on) its DM1/DM2 at its own source address."""

    def __init__(
        self, lc: LoopConfig, cfg: MonitorConfig, codec: FrameCodec, view: tuple[str, ...]
    ) -> None:
        self.cfg = lc
        self.name = lc.name
        self.view = view
        self.model, self.ticker = self.load(lc, cfg, view)
        self.digest = file_digest(lc.model)  # a reload keeps the ticker if this is unchanged
        self.frames = AlarmFrames(codec, cfg.outputs, lc.alarm_message)
        self.diag: Diagnostics | None = None
        if cfg.j1939.enabled:
            j1939 = replace(cfg.j1939, source_address=lc.source_address)
            self.diag = Diagnostics(j1939, self.model.spec.variables, view)
        self.tag = {"loop": lc.name} if cfg.loops else {}  # events name the loop when loops are set
        self.last_j = float("nan")
        self.last_level = float("nan")  # max(J / eps0, B / b0) of the last tick, 1 = alarm

    @staticmethod
    def load(
        lc: LoopConfig, cfg: MonitorConfig, view: tuple[str, ...]
    ) -> tuple[MonitorModel, Ticker]:
        """The loop's model and a fresh ticker (raises on a bad model file, or one of
        another loop or machine)."""
        model = load_model(lc.model)
        check_loop_model(model, lc, cfg)
        return model, Ticker(model, cfg.alarm, cfg.horizon, columns=view, gating=cfg.gating)

    def swap(
        self,
        lc: LoopConfig,
        cfg: MonitorConfig,
        new: tuple[MonitorModel, Ticker, str] | None = None,
    ) -> None:
        """A reload: ``new`` (model, ticker, model file digest) takes over from the running
        ticker's alarm state (``Ticker.carry_over``); None keeps model and ticker.  Frames
        and DTC history go on."""
        self.cfg = lc
        self.frames.cfg = cfg.outputs
        if new is not None:
            model, ticker, self.digest = new
            ticker.carry_over(self.ticker)
            self.model, self.ticker = model, ticker

    @property
    def state(self) -> State:
        return self.ticker.state

    def tick(self, row: np.ndarray) -> Tick:
        tick = self.ticker.tick(row)
        self.last_j, self.last_level = tick.j, tick.level
        return tick

    def event(self, tick: Tick, start_time_s: float | None) -> dict[str, Any]:
        return event(tick, self.ticker.fault, self.ticker.eps0, start_time_s) | self.tag

    def alarm_label(self) -> str:
        """The black-box file's label of this loop's alarm."""
        return f"{self.name}-{self.ticker.fault}" if self.tag else self.ticker.fault

    def dm_frames(self, tick: Tick, bus_time_s: float, row: np.ndarray) -> list[can.Message]:
        """This row's DM1/DM2 frames of the loop (none with J1939 off)."""
        if self.diag is None:
            return []
        named = finding(tick.check, tick.sensor)
        return self.diag.tick(tick.t_s, bus_time_s, tick.state, self.ticker.fault, row, named,
                              tick.episode_open)  # fmt: skip


def loop_recording(path: str | Path, cfg: MonitorConfig, name: str) -> Recording:
    """Loop ``name``'s signals of a candump log with several loops' frames, under the
    contract names, on the daemon's sample clock (which starts at the first frame of any
    loop, so the rows are the ones the daemon ticks)."""
    names = [lc.name for lc in cfg.monitored_loops]
    if name not in names:
        raise ConfigError(f"{cfg.source}: no loop {name!r}; loops: {', '.join(names)}")
    if Path(path).suffix.lower() == ".csv":
        raise InputFileError(f"{path}: a contract CSV holds one loop; --loop reads a candump log")
    codec = FrameCodec.from_dbc(cfg.dbc)
    columns, views = row_layout(cfg, codec)
    rods = {lc.dbc_signal(ROD_POS.name) for lc in cfg.monitored_loops} - {None}
    wide = recording_from_candump_bulk(path, codec, columns, optional=rods)
    view = views[names.index(name)]
    picked = {
        contract: wide[col]
        for col, contract in zip(columns, view, strict=True)
        if not contract.startswith(_OTHER) and wide.has(col)
    }
    # The signals the loop renames are its own; a log without any of them is not its log.
    own = [col for col, c in zip(columns, view, strict=True)
           if not c.startswith(_OTHER) and col != c]  # fmt: skip
    if own and not any(wide.has(c) and np.isfinite(wide[c]).any() for c in own):
        raise NoHydraulicDataError(f"{path}: no frame carries loop {name}'s own signals "
                                   f"({', '.join(own)}) in {cfg.dbc}")  # fmt: skip
    rod = picked.get(ROD_POS.name)
    if rod is not None and not np.isfinite(rod).any():
        del picked[ROD_POS.name]  # as without a rod sensor: the column is left out
    meta = {**wide.meta, "loop": name}
    return Recording(t=wide.t, columns=picked, source=f"{path} (loop {name})", meta=meta)


def read_loop(path: str | Path, cfg: MonitorConfig, name: str | None) -> Recording:
    """``monitor detect``/``train`` input: loop ``name`` of a log with several loops, or
    (``name`` None) the recording itself."""
    if name is None:
        return read_recording(path, cfg.dbc)  # the config's DBC, as the daemon reads the bus
    if Path(path).is_dir():
        raise InputFileError(f"{path}: is a folder; give a recording (.log or .csv) in it")
    if not Path(path).is_file():
        raise InputFileError(f"{path}: no such file")
    return loop_recording(path, cfg, name)


def wide_recording(cfg: MonitorConfig, recordings: dict[str, Recording]) -> Recording:
    """The inverse of ``loop_recording``: one recording per loop (contract names, one
    time base) as one recording under the DBC's signal names, for ``write_candump`` with
    the config's DBC.  A signal several loops share (EngineSpeed, OilTemp) comes from the
    first loop's recording."""
    loops = cfg.monitored_loops
    missing = [lc.name for lc in loops if lc.name not in recordings]
    if missing:
        raise ValueError(f"no recording for loop(s) {', '.join(missing)}")
    first = recordings[loops[0].name]
    columns: dict[str, np.ndarray] = {}
    for lc in loops:
        rec = recordings[lc.name]
        if len(rec) != len(first) or not np.allclose(rec.t, first.t):
            raise ValueError(f"loop {lc.name}'s recording is not on the first loop's time base")
        for contract in ROW_COLUMNS:
            name = lc.dbc_signal(contract)
            if name is not None and rec.has(contract) and name not in columns:
                columns[name] = rec[contract]
    return Recording(t=first.t, columns=columns, source="+".join(recordings), meta={})


def check_loop_model(model: MonitorModel, lc: LoopConfig, cfg: MonitorConfig,
                     path: str | Path | None = None) -> None:
    """Refuse ``model`` (from ``path``, default the loop's) for loop ``lc`` of ``cfg`` when
    it was trained on another loop or machine (``monitor.model.machinecard``)."""
    where = f"{cfg.source}: loops[{cfg.loops.index(lc)}]" if lc in cfg.loops else str(cfg.source)
    if lc.machine_source is not None:
        where += f" (machine {lc.machine_source.name})"
    check_model_for_loop(model.card, model.envelope, path or lc.model, lc.name, lc.machine,
                         where)  # fmt: skip


def file_digest(path: str | Path) -> str:
    """SHA-256 of a file's bytes: whether a reload brings a different model."""
    h = hashlib.sha256()
    with Path(path).open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()
