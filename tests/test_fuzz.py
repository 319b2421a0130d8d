"""Property-based fuzzing of every reader of user files: candump logs, contract CSVs,
configuration YAML and model files.

The property: a reader returns a result or raises a ``MonitorError`` subclass whose message
is one line of bounded length; never another exception (which the CLI would show as a
traceback).  Inputs stay small; big inputs are the readers' limits' business
(tests/test_input_limits.py).

``MONITOR_FUZZ_EXAMPLES`` sets the examples per test (default: 150-200, under a minute
in all, derandomized so CI is repeatable); e.g. ``MONITOR_FUZZ_EXAMPLES=5000`` for a long
random run.  The counts of inputs and outcomes are printed in the terminal summary.
"""

from __future__ import annotations

import io
import json
import math
import os
import re
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from fuzz_support import outcome
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from naive_frames import recording_from_candump

from monitor.config.settings import load_config
from monitor.io.candump import read_candump
from monitor.io.candump_bulk import read_candump_frames
from monitor.io.csvio import read_csv
from monitor.model.modelfile import _checksum, load_model
from monitor.resources import resource_path
from monitor.sampling.read import read_recording

_ENV = os.environ.get("MONITOR_FUZZ_EXAMPLES")


def fuzz(examples: int):
    """Hypothesis settings: ``examples`` by default, MONITOR_FUZZ_EXAMPLES when given."""
    return settings(
        max_examples=int(_ENV) if _ENV else examples,
        deadline=None,
        derandomize=not _ENV,  # CI: the same inputs every run
        database=None,  # nothing written into the checkout
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    )


@pytest.fixture(scope="module")
def work() -> Path:
    """A folder for the inputs (hypothesis runs many examples per test call, so no tmp_path)."""
    with tempfile.TemporaryDirectory(prefix="monitor-fuzz-") as d:
        yield Path(d)


def _write(path: Path, data: bytes | str) -> Path:
    path.write_bytes(data.encode("utf-8", "surrogatepass") if isinstance(data, str) else data)
    return path


# --------------------------------------------------------------------------- candump

_LOG_LINES = resource_path("replay", "spool_wear.log").read_text().splitlines()[:400]

hexdigits = st.text("0123456789abcdefABCDEF", max_size=20)
stamp = st.one_of(
    st.from_regex(r"\A\d{1,12}\.\d{1,9}\Z"),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(min_value=0, max_value=10**40).map(lambda n: f"{n}.{n % 1000:06d}"),
    st.sampled_from(["1e20", "-1.0", "1.", ".5", "1" * 400 + ".0", "0" * 25 + "1.5", ""]),
    st.text(max_size=12),
)
near_line = st.builds(
    lambda ts, sep1, iface, sep2, ident, hash_, data, tail: (
        f"({ts}){sep1}{iface}{sep2}{ident}{hash_}{data}{tail}"
    ),
    stamp,
    st.sampled_from([" ", "\t", "  ", ""]),
    st.sampled_from(["can0", "vcan0", "x", ""]) | st.text(max_size=5),
    st.sampled_from([" ", "\t", ""]),
    st.sampled_from(["0CFF1021", "0CFF1121", "18FF1300", "123", "7FF", "20000080"]) | hexdigits,
    st.sampled_from(["#", "##", ""]),
    hexdigits | st.sampled_from(["R", "r8", "1001122"]),
    st.sampled_from(["", " T", " R", "\r", " x"]),
)
line_end = st.sampled_from(["\n", "\r\n", "\r", ""])


@st.composite
def near_valid_logs(draw) -> bytes:
    """Lines of a shipped log (whose frames decode) with a few edits: clock jumps back and
    forth, lost, swapped or broken lines, stray bytes, a cut."""
    n = draw(st.integers(1, 120))
    start = draw(st.integers(0, len(_LOG_LINES) - n))
    rests = [x[x.index(")") + 1 :] for x in _LOG_LINES[start : start + n]]
    times = [1_700_000_000.0 + i * 0.0025 for i in range(n)]
    stamps: list[str | None] = [None] * n
    ends = ["\n"] * n
    for _ in range(draw(st.integers(0, 4))):
        i = draw(st.integers(0, n - 1))
        edit = draw(
            st.sampled_from(["jump", "jump", "jump", "swap", "drop", "stamp", "line", "end"])
        )
        if edit == "jump":  # the clock of every later frame moves
            dt = draw(st.sampled_from([0.005, -0.005, -3.0, -3600.0, 59.9, 61.0, 3600.0, 1e6]))
            times[i:] = [t + dt for t in times[i:]]
        elif edit == "swap" and i + 1 < n:
            rests[i], rests[i + 1] = rests[i + 1], rests[i]
        elif edit == "drop":
            rests[i] = ""
        elif edit == "stamp":
            stamps[i] = draw(stamp)
        elif edit == "end":
            ends[i] = draw(st.sampled_from(["\r\n", "\r", "", " \n", "\n\n"]))
        else:
            rests[i] = "\0" + draw(near_line)  # a whole line of its own, see below
    out = []
    for t, s, rest, end in zip(times, stamps, rests, ends, strict=True):
        if not rest:
            continue
        line = (
            rest[1:]
            if rest.startswith("\0")
            else f"({t:.6f}){rest}"
            if s is None
            else f"({s}){rest}"
        )
        out.append(line + end)
    data = "".join(out).encode("utf-8", "surrogatepass")
    if draw(st.integers(0, 5)) == 0:  # stray bytes somewhere
        pos = draw(st.integers(0, len(data)))
        data = data[:pos] + draw(st.binary(max_size=8)) + data[pos:]
    if draw(st.integers(0, 5)) == 0 and data:  # cut off anywhere
        data = data[: draw(st.integers(0, len(data)))]
    return data


# The bulk reader refuses a binary file (NULs, a long line) while reading, before looking at
# any line; the line-by-line reader may meet an earlier malformed line first.
_READ_TIME_REFUSAL = re.compile(r":\d+: (NUL bytes|line longer than)")

CANDUMP_READERS = {
    "candump bulk frames": read_candump_frames,
    "candump python-can": lambda p: list(read_candump(p)),
    "candump recording (bulk)": read_recording,
    "candump recording (frame by frame)": recording_from_candump,
}


@fuzz(150)
@given(data=st.binary(max_size=600))
def test_candump_readers_on_random_bytes(work, data: bytes) -> None:
    path = _write(work / "random.log", data)
    for name, read in CANDUMP_READERS.items():
        outcome(f"{name}, random bytes", lambda r=read: r(path), path)


@fuzz(150)
@given(data=near_valid_logs())
# found: a lone CR ended a line for python-can's reader, not for the bulk one
@example(data=_LOG_LINES[0].encode() + b"\r" + _LOG_LINES[1].encode() + b"\n")
@example(data=b"\x00(0.0) can0 0CFF1021#\n")  # found: the two NUL messages differed
def test_candump_readers_on_near_valid_logs(work, data: bytes) -> None:
    """Also: the bulk path and the daemon's frame-by-frame path agree (same frames, same
    rows, or the same error)."""
    path = _write(work / "near.log", data)
    got = {
        name: outcome(f"{name}, near-valid logs", lambda r=read: r(path), path)
        for name, read in CANDUMP_READERS.items()
    }
    (k1, frames), (k2, msgs) = got["candump bulk frames"], got["candump python-can"]
    assert k1 == k2
    if k1 == "ok":
        assert frames.timestamp.tolist() == [m.timestamp for m in msgs]
    elif not _READ_TIME_REFUSAL.search(frames):
        assert frames == msgs
    (k1, bulk), (k2, slow) = (
        got["candump recording (bulk)"],
        got["candump recording (frame by frame)"],
    )
    assert k1 == k2
    if k1 == "ok":
        assert np.array_equal(bulk.t, slow.t)
        assert bulk.columns.keys() == slow.columns.keys()
        for name, col in bulk.columns.items():
            assert np.array_equal(col, slow.columns[name], equal_nan=True), name
        assert bulk.meta == slow.meta
    elif not _READ_TIME_REFUSAL.search(bulk):
        assert bulk == slow


# ------------------------------------------------------------------------------- CSV

_CSV = (
    "t,SpoolCmd,PumpDispCmd,EngineSpeed,OilTemp,PP,PA,PB,QP,RodPos\n"
    "0.000000,10,50,1800,45,120.5,80.25,10,55,300\n"
    "0.010000,10.5,50,1800,45,121,80,10.5,55.5,301\n"
    "0.020000,,50,1800,45,122,80,11,56,302\n"
)
csv_cell = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(["", "nan", "inf", "-1e400", "1e400", "0x10", "1_0", " 1 ", '"1"', '"']),
    st.text(max_size=8),
)


@st.composite
def near_valid_csvs(draw) -> str:
    rows = [r.split(",") for r in _CSV.splitlines()]
    for _ in range(draw(st.integers(0, 3))):
        r = draw(st.integers(0, len(rows) - 1))
        action = draw(st.sampled_from(["cell", "cell", "drop_cell", "add_cell", "dup_row"]))
        if action == "cell" and rows[r]:
            rows[r][draw(st.integers(0, len(rows[r]) - 1))] = draw(csv_cell)
        elif action == "drop_cell" and rows[r]:
            rows[r].pop(draw(st.integers(0, len(rows[r]) - 1)))
        elif action == "add_cell":
            rows[r].append(draw(csv_cell))
        else:
            rows.insert(r, list(rows[r]))
    ends = st.sampled_from(["\n"] * 9 + ["\r\n", "\r", ""])
    return "".join(",".join(r) + draw(ends) for r in rows)


@fuzz(200)
@given(data=st.binary(max_size=400) | st.text(max_size=400).map(str.encode))
def test_csv_reader_on_random_input(work, data: bytes) -> None:
    path = _write(work / "random.csv", data)
    outcome("csv, random input", lambda: read_csv(path), path)
    outcome("recording from .csv, random input", lambda: read_recording(path), path)


@fuzz(200)
@given(text=near_valid_csvs())
@example(text='"' + _CSV)  # found: the whole file quoted in the missing-columns message
def test_csv_reader_on_near_valid_csvs(work, text: str) -> None:
    path = _write(work / "near.csv", text)
    outcome("csv, near-valid", lambda: read_csv(path), path)


# ---------------------------------------------------------------------------- config

_CONFIG = yaml.safe_load(resource_path("config", "monitor.yaml").read_text())
json_scalar = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=30),
)
json_value = st.recursive(
    json_scalar,
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4)
    ),
    max_leaves=12,
)


def _leaves(node: Any, path: tuple = ()) -> list[tuple]:
    """Paths to every value of a nested dict/list (the containers included)."""
    out = [path]
    if isinstance(node, dict):
        for k, v in node.items():
            out += _leaves(v, (*path, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out += _leaves(v, (*path, i))
    return out


@st.composite
def mutated(draw, base: Any) -> Any:
    """``base`` (a JSON-like tree) with a few values replaced, deleted or keys added."""
    doc = json.loads(json.dumps(base))
    for _ in range(draw(st.integers(1, 4))):
        paths = _leaves(doc)
        path = draw(st.sampled_from(paths[1:] or paths))
        if not path:
            return draw(json_value)
        parent = doc
        for k in path[:-1]:
            parent = parent[k]
        action = draw(st.sampled_from(["replace", "replace", "delete", "add"]))
        if action == "replace":
            parent[path[-1]] = draw(json_value)
        elif action == "delete":
            del parent[path[-1]]
        elif isinstance(parent, dict):
            parent[draw(st.text(max_size=10))] = draw(json_value)
    return doc


def _config_with_paths(doc: Any) -> Any:
    # The shipped config's dbc and model are relative to config/; the fuzzed copy lives
    # elsewhere, so point them at the shipped files unless the fuzzer changed them.
    if isinstance(doc, dict):
        for key, name in (
            ("dbc", ("dbc", "monitor.dbc")),
            ("model", ("config", "boom_default.model.npz")),
        ):
            if doc.get(key) == _CONFIG.get(key):
                doc[key] = str(resource_path(*name))
    return doc


@fuzz(200)
@given(doc=mutated(_CONFIG))
@example(doc={**_CONFIG, "\n": 1})  # found: a key with a newline split the message
@example(doc={**_CONFIG, "detector": {"\n": 1}})
@example(doc={**_CONFIG, **{f"k{i}": i for i in range(500)}})
@example(doc={**_CONFIG, "alarm": {"raise_samples": "x" * 5000}})
def test_config_loader_on_mutated_configs(work, doc: Any) -> None:
    path = _write(work / "mutated.yaml", yaml.safe_dump(_config_with_paths(doc)))
    outcome("config, mutated shipped", lambda: load_config(path), path)


yaml_text = st.one_of(
    st.text(max_size=300),
    st.lists(
        st.sampled_from(
            [
                "bus:",
                "  channel: can0",
                "alarm: {raise_samples: 1e400}",
                "- x",
                "&a [*a]",
                "? x",
                "!!python/object:os.system x",
                "loops:",
                "  - {",
                "event_log: {path: ''}",
                "dbc: .",
                "\t",
                "'",
                "%YAML 1.1",
                "---",
                "detector: {horizon: .nan}",
                "storage: {quota_mb: -1}",
                "[[[[[[",
            ]
        ),
        max_size=12,
    ).map("\n".join),
)


@fuzz(200)
@given(text=yaml_text)
def test_config_loader_on_random_yaml(work, text: str) -> None:
    path = _write(work / "random.yaml", text)
    outcome("config, random YAML", lambda: load_config(path), path)


# ----------------------------------------------------------------------------- model

_MODEL_PATH = resource_path("config", "boom_default.model.npz")
_MODEL_BYTES = _MODEL_PATH.read_bytes()
with np.load(_MODEL_PATH) as _npz:
    _MODEL = {k: _npz[k] for k in _npz.files}
_HEADER = json.loads(_MODEL["header"].tobytes())


def _save(path: Path, arrays: dict[str, np.ndarray], header: Any) -> Path:
    """A model file with ``header`` and a valid checksum over it (so the checks behind the
    checksum are reached)."""
    head = json.dumps(header).encode()
    arrays = dict(arrays)
    arrays["header"] = np.frombuffer(head, dtype=np.uint8)
    try:
        checksum = _checksum(head, arrays).encode()
    except (KeyError, ValueError, TypeError):
        checksum = b"0" * 64  # an array the checksum cannot take: the loader says which
    arrays["checksum"] = np.frombuffer(checksum, dtype=np.uint8)
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return _write(path, buf.getvalue())


@fuzz(150)
@given(st.data())
def test_model_loader_on_corrupted_files(work, data) -> None:
    raw = bytearray(_MODEL_BYTES)
    for _ in range(data.draw(st.integers(1, 8))):
        pos = data.draw(st.integers(0, len(raw) - 1))
        raw[pos] = data.draw(st.integers(0, 255))
    if data.draw(st.booleans()):
        raw = raw[: data.draw(st.integers(0, len(raw)))]
    path = _write(work / "corrupt.model.npz", bytes(raw))
    outcome("model, corrupted bytes", lambda: load_model(path), path)


@fuzz(200)
@given(header=mutated(_HEADER))
# found: a bad spec quoted whole; a bad name without a stored envelope (ValueError)
@example(header={**_HEADER, "spec": {**_HEADER["spec"], "outputs": None}})
@example(
    header={
        **{k: v for k, v in _HEADER.items() if k != "validity"},
        "normalizer": {
            **_HEADER["normalizer"],
            "names": [None, *_HEADER["normalizer"]["names"][1:]],
        },
    }
)
def test_model_loader_on_mutated_headers(work, header: Any) -> None:
    path = _save(work / "header.model.npz", _MODEL, header)
    outcome("model, mutated header (valid checksum)", lambda: load_model(path), path)


array_change = st.sampled_from(["nan", "inf", "shape", "dtype", "empty", "drop", "extra"])


@fuzz(150)
@given(
    name=st.sampled_from(sorted(k for k in _MODEL if k not in ("header", "checksum"))),
    change=array_change,
    seed=st.integers(0, 2**32 - 1),
)
def test_model_loader_on_mutated_arrays(work, name: str, change: str, seed: int) -> None:
    rng = np.random.default_rng(seed)
    arrays = {k: v for k, v in _MODEL.items() if k not in ("header", "checksum")}
    a = arrays[name].copy()
    if change in ("nan", "inf") and a.dtype.kind == "f" and a.size:
        a.flat[rng.integers(0, a.size)] = math.nan if change == "nan" else -math.inf
    elif change == "shape":
        a = a.reshape(-1)[: max(a.size - int(rng.integers(1, 50)), 0)]
        a = a.reshape(-1, 1) if rng.integers(2) else a
    elif change == "dtype":
        a = a.astype(np.float32 if a.dtype.kind != "f" else np.int64)
    elif change == "empty":
        a = a[:0]
    elif change == "drop":
        del arrays[name]
        a = None
    else:
        arrays["extra"] = rng.random(5)
    if a is not None:
        arrays[name] = a
    path = _save(work / "arrays.model.npz", arrays, _HEADER)
    outcome("model, mutated arrays (valid checksum)", lambda: load_model(path), path)
