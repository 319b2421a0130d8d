"""Hangs and tracebacks a user or an attacker can cause at the daemon's edges, each bounded
and one line with an exit code: a FIFO as ``--config``, a hung SIGHUP reload, a 4,000-digit
integer in the config, a model whose array header claims 8 TiB, a 0-byte DM1 frame under
``monitor watch``."""

from __future__ import annotations

import io
import os
import subprocess
import sys
import threading
import time
import zipfile
from pathlib import Path

import can
import pytest
from live_support import REPO, write_config
from numpy.lib import format as npy

from monitor.cli import main
from monitor.codec.frames import FrameCodec
from monitor.errors import ModelFileError
from monitor.live import reload as reload_module
from monitor.model.modelfile import load_model
from monitor.resources import resource_path
from monitor.watch.state import WatchState

MODEL = resource_path("config", "boom_default.model.npz")


def _one_error_line(err: str, *needles: str) -> None:
    lines = [x for x in err.splitlines() if x.strip()]
    assert len(lines) == 1, err[-2000:]
    assert lines[0].startswith("monitor run: error: ")
    assert all(n in lines[0] for n in needles), lines[0][:300]


def test_a_fifo_as_config_is_refused_at_once(tmp_path) -> None:
    fifo = tmp_path / "monitor.yaml"
    os.mkfifo(fifo)
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    try:  # the timeout detects a hang; it is no timing
        r = subprocess.run(
            [sys.executable, "-m", "monitor", "run", "--config", str(fifo)],
            capture_output=True,
            text=True,
            env=env,
            timeout=120,
        )
    except subprocess.TimeoutExpired:
        pytest.fail("monitor run hung on a FIFO as --config")
    assert r.returncode == 2
    _one_error_line(r.stderr, str(fifo), "not a regular file")


@pytest.mark.parametrize("digits", [4000, 5000])
def test_a_huge_integer_in_the_config_is_one_line(tmp_path, capsys, digits: int) -> None:
    cfg = write_config(tmp_path, "outputs:\n  frames_max_per_s: " + "9" * digits + "\n")
    assert main(["run", "--config", str(cfg)]) == 2
    err = capsys.readouterr().err
    _one_error_line(err, str(cfg))
    assert len(err) < 400
    if digits == 4000:  # a Python int, beyond any float
        assert "frames_max_per_s must be a finite number" in err
    else:  # more digits than Python converts to an int
        assert "line 5: an integer of 5000 characters" in err  # after dbc, model, machine_id


def _model_claiming(tmp_path: Path, shape: tuple[int, ...]) -> Path:
    """The shipped model with the ``patterns`` header claiming ``shape`` (data unchanged)."""
    out = tmp_path / "claims.model.npz"
    with zipfile.ZipFile(MODEL) as zin, zipfile.ZipFile(out, "w") as zout:
        for info in zin.infolist():
            data = zin.read(info.filename)
            if info.filename == "patterns.npy":
                fh = io.BytesIO(data)
                npy.read_magic(fh)
                _, fortran, dtype = npy.read_array_header_1_0(fh)
                head = io.BytesIO()
                npy.write_array_header_1_0(
                    head,
                    {"descr": npy.dtype_to_descr(dtype), "fortran_order": fortran, "shape": shape},
                )
                data = head.getvalue() + data[fh.tell() :]
            zout.writestr(info, data)
    return out


def test_a_model_header_claiming_8_tib_is_refused_before_allocating(tmp_path, capsys) -> None:
    model = _model_claiming(tmp_path, (2**40, 1))  # 8 TiB of float64
    with pytest.raises(ModelFileError, match="claims shape"):
        load_model(model)
    cfg = write_config(tmp_path, "", model=model)
    assert main(["run", "--config", str(cfg)]) == 2  # at the daemon's start too
    _one_error_line(capsys.readouterr().err, str(model), "8,796,093,022,208 bytes")


def test_a_model_header_claiming_less_than_its_data_is_refused(tmp_path) -> None:
    with pytest.raises(ModelFileError, match="claims shape"):
        load_model(_model_claiming(tmp_path, (3, 11)))


def test_one_hung_reload_never_disables_sighup(monkeypatch) -> None:
    """The first reload hangs (a file on a dead mount); it is given up, and the SIGHUP
    after it (and one that came while it hung) reloads; the hung one's late result is
    dropped."""
    monkeypatch.setattr(reload_module, "RELOAD_LIMIT_S", 0.2)
    release = threading.Event()
    calls: list[int] = []

    def prepare() -> Exception:
        calls.append(len(calls) + 1)
        if len(calls) == 1:
            release.wait(120)
        return ValueError(f"result of reload {len(calls)}")

    r = reload_module.Reloader(prepare)
    r.request()
    got = _poll_until(r)
    assert isinstance(got, TimeoutError)
    r.request()  # the next SIGHUP
    got = _poll_until(r)
    assert isinstance(got, ValueError) and str(got) == "result of reload 2"
    release.set()  # the hung one returns at last: its result is never applied
    time.sleep(0.5)
    assert r.poll() is None and calls == [1, 2]


def _poll_until(r: reload_module.Reloader, timeout_s: float = 60.0) -> object:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        got = r.poll()
        if got is not None:
            return got
        time.sleep(0.02)
    raise AssertionError("no reload result: SIGHUP is dead")


@pytest.mark.parametrize("data", [b"", b"\x00"])
def test_watch_counts_a_dm1_frame_too_short_for_its_lamps(data: bytes) -> None:
    state = WatchState(FrameCodec.from_dbc(None))
    state.feed(can.Message(arbitration_id=0x18FECAA0, data=data, is_extended_id=True))
    assert state.rejected == {"DM1": 1} and state.dm1 == {}
    state.feed(
        can.Message(
            arbitration_id=0x18FECAA0,
            is_extended_id=True,
            data=bytes([0x04, 0xFF, 0x00, 0xF0, 0xE7, 0x01, 0xFF, 0xFF]),
        )
    )
    assert [(d.spn, d.fmi, d.oc) for d in state.dm1[0xA0][1]] == [(520192, 7, 1)]
