"""Recordings of one loop of a log with several loops' frames, and several loops' recordings
as one: ``monitor detect``/``train --loop``, the fleet and the benchmarks read logs here, on
the daemon's row layout (``monitor.config.layout``) and sample clock, without the daemon.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from monitor.codec.frames import FrameCodec
from monitor.config.layout import OTHER, rod_columns, row_layout
from monitor.config.settings import MonitorConfig
from monitor.errors import ConfigError, InputFileError, NoHydraulicDataError
from monitor.io.csvio import read_csv
from monitor.io.recording import Recording
from monitor.sampling.bulk import recording_from_candump_bulk
from monitor.sampling.read import read_recording
from monitor.sampling.sampler import ROW_COLUMNS
from monitor.signals import ROD_POS, is_neighbour


def loop_recording(path: str | Path, cfg: MonitorConfig, name: str) -> Recording:
    """Loop ``name``'s signals of a log with several loops' frames, under the contract
    names, on the daemon's sample clock (which starts at the first frame of any loop, so the
    rows are the ones the daemon ticks), with the other loops' spool commands as
    ``SpoolCmd@LOOP`` (``monitor.signals.neighbour``).  A ``.csv`` is a whole-machine
    CSV whose columns are the DBC's signal names (``t`` and the loop's own required)."""
    return loop_recordings(path, cfg, (name,))[name]


def loop_recordings(
    path: str | Path, cfg: MonitorConfig, names: Sequence[str]
) -> dict[str, Recording]:
    """``loop_recording`` of each loop of ``names``, the file read once."""
    known = _check_names(cfg, names)
    codec = FrameCodec.from_dbc(cfg.dbc)
    columns, views = row_layout(cfg, codec)
    optional = rod_columns(cfg.monitored_loops)
    if Path(path).suffix.lower() == ".csv":
        mine = {
            c
            for name in names
            for c, v in zip(columns, views[known.index(name)], strict=True)
            if v in ROW_COLUMNS and c not in optional
        }
        wide = read_csv(path, required=[c for c in columns if c in mine])
    else:
        wide = recording_from_candump_bulk(path, codec, columns, optional=optional)
    return {name: _pick(wide, columns, views[known.index(name)], name, path, cfg) for name in names}


def split_loops(
    wide: Recording, cfg: MonitorConfig, names: Sequence[str], source: str
) -> dict[str, Recording]:
    """``loop_recordings`` of a recording already in memory under the DBC's signal names
    (a whole-machine simulation, as its CSV would be read back): each loop of ``names``."""
    known = _check_names(cfg, names)
    columns, views = row_layout(cfg, FrameCodec.from_dbc(cfg.dbc))
    return {
        name: _pick(wide, columns, views[known.index(name)], name, source, cfg) for name in names
    }


def _check_names(cfg: MonitorConfig, names: Sequence[str]) -> list[str]:
    """The config's loop names; a name of ``names`` not among them is a ``ConfigError``."""
    known = [lc.name for lc in cfg.monitored_loops]
    for name in names:
        if name not in known:
            raise ConfigError(f"{cfg.source}: no loop {name!r}; loops: {', '.join(known)}")
    return known


def _pick(
    wide: Recording,
    columns: Sequence[str],
    view: Sequence[str],
    name: str,
    path: str | Path,
    cfg: MonitorConfig,
) -> Recording:
    """Loop ``name``'s columns of the row ``wide`` under their ``view`` names."""
    picked = {
        contract: wide[col]
        for col, contract in zip(columns, view, strict=True)
        if not contract.startswith(OTHER) and wide.has(col)
    }
    # The signals the loop renames are its own; a log without any of them is not its log.
    own = [
        col
        for col, c in zip(columns, view, strict=True)
        if not c.startswith(OTHER) and not is_neighbour(c) and col != c
    ]
    if own and not any(wide.has(c) and np.isfinite(wide[c]).any() for c in own):
        raise NoHydraulicDataError(
            f"{path}: no frame carries loop {name}'s own signals ({', '.join(own)}) in {cfg.dbc}"
        )
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


def machine_rows(
    path: str | Path, cfg: MonitorConfig
) -> tuple[tuple[str, ...], np.ndarray, float | None]:
    """The daemon's rows of a whole-machine recording (candump log, or a CSV whose columns
    are the DBC's signal names): (columns, ``[t, *columns]`` rows, NaN where a signal is
    missing, and the log time of the first row, None for a CSV), as the daemon's sampler
    makes them; what the pump rule reads."""
    if Path(path).is_dir():
        raise InputFileError(f"{path}: is a folder; give a recording (.log or .csv) in it")
    if not Path(path).is_file():
        raise InputFileError(f"{path}: no such file")
    codec = FrameCodec.from_dbc(cfg.dbc)
    columns, _ = row_layout(cfg, codec)
    optional = rod_columns(cfg.monitored_loops)
    if Path(path).suffix.lower() == ".csv":
        wide = read_csv(path, required=[c for c in columns if c not in optional])
    else:
        wide = recording_from_candump_bulk(path, codec, columns, optional=optional)
    start = wide.meta.get("start_time_s")
    start_s = float(start) if isinstance(start, (int, float)) else None
    return columns, rows_of(wide, columns), start_s


def rows_of(wide: Recording, columns: Sequence[str]) -> np.ndarray:
    """``[t, *columns]`` rows of a recording under the DBC's signal names (NaN: absent)."""
    nan = np.full(len(wide), np.nan)
    return np.column_stack([wide.t, *[wide[c] if wide.has(c) else nan for c in columns]])
