"""`monitor demo --machine excavator4`: four loops on one virtual bus, the stick's spool worn.

The daemon's events are checked against an independent path: the same run simulated by
`monitor simulate --machine excavator4` to a candump log and judged offline loop by loop by
`monitor detect --loop` (the daemon and detect share their decisions, so their state changes
must agree), and the MON_Alarm frames read back per loop against those events."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from monitor.cli import _demo_machine as demo
from monitor.cli import main
from monitor.resources import resource_path

LOOPS = ("boom", "stick", "bucket", "swing")


def _changes(lines: list[dict]) -> dict[str, list[tuple[float, str]]]:
    """Each loop's state changes (t, state) of event lines."""
    out: dict[str, list[tuple[float, str]]] = {n: [] for n in LOOPS}
    for x in lines:
        # The pump rule's lines (loop "pump") are checked in test_pump_live.
        if "state" in x and x.get("event") in (None, "state") and x["loop"] in out:
            out[x["loop"]].append((x["t"], x["state"]))
    return out


def test_four_loops_on_one_bus_raise_the_faulty_loops_alarm_alone(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    assert main(["demo", "--machine", "excavator4", "--speed", "40", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    events = [json.loads(x) for x in (tmp_path / "events.jsonl").read_text().splitlines()]
    live = _changes(events)

    log = tmp_path / "same.log"
    fault = f"{demo.FAULTY_LOOP}.{demo.FAULT}:{demo.SEVERITY:g}@{demo.ONSET_S:g}"
    argv = [
        "simulate",
        "--machine",
        "excavator4",
        "--duration",
        f"{demo.SPAN_S:g}",
        "--seed",
        str(demo.SEED),
        "--fault",
        fault,
        "--out",
        str(log),
    ]
    assert main(argv) == 0
    config = str(resource_path("config", "excavator4.yaml"))
    for loop in LOOPS:
        ev = tmp_path / f"{loop}.jsonl"
        argv = [
            "detect",
            str(log),
            "--loop",
            loop,
            "--config",
            config,
            "--events",
            str(ev),
            "--j-every",
            "0",
        ]
        assert main(argv) == 0
        offline = _changes([json.loads(x) for x in ev.read_text().splitlines()])[loop]
        if live[loop][-1][1] == "inactive" and offline[-1][1] != "inactive":
            # The bus fell silent after the log (the daemon's clock runs on): not the log's.
            assert live[loop][-1][0] >= demo.SPAN_S - 0.5
            live[loop].pop()
        assert [s for _, s in live[loop]] == [s for _, s in offline], loop
        assert [t for t, _ in live[loop]] == pytest.approx([t for t, _ in offline], abs=0.011)

    # The stick's worn spool raises the stick's alarm after the onset, and no other loop's.
    faults = {n: [t for t, s in live[n] if s == "fault"] for n in LOOPS}
    assert faults["stick"] and faults["stick"][0] >= demo.ONSET_S
    assert not any(faults[n] for n in LOOPS if n != "stick")
    delay = faults["stick"][0] - demo.ONSET_S
    assert (
        f"stick (the faulty loop): hydraulic fault raised at {faults['stick'][0]:.2f} s of the "
        f"log, {delay:.2f} s after the fault's onset" in out
    )
    assert "the fault raised the stick's alarm, no neighbour's" in out
    for loop in ("boom", "bucket", "swing"):
        assert f"  {loop}: no alarm;" in out
    assert ", 0 dropped;" in out
