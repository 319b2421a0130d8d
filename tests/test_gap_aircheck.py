"""Entrained air read at rest (``judge/aircheck.py``) and the verdict it decides
(``diagnose/atrest.py``), on recordings made with ``monitor simulate`` and with the third
plant written apart (benchmarks/gap_third).

Expected values from the physics the simulator was given.  A worn piston seal (fault
``piston_wear``) leaks from the loaded chamber into the drained one while the rod rests on
an end stop; the same flow Q makes the loaded chamber fall at Q / C_loaded and the drained
one rise at Q / C_drained.  With pure oil C = V / beta, and on the bottom stop the drained
cap side holds its 0.3 L dead volume against the rod side's 0.3 + 1.05 L: the drained
chamber rises some 4.5 times as fast as the loaded one falls.  With 1 % of free air at
atmospheric pressure (isothermal) the drained chamber near 1 bar absolute is
0.01 V / p0 soft, 150 times the oil's V / beta: its rise all but stops."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks.gap_third.scenario import Scenario, record
from monitor.cli import main
from monitor.gap.data.prepare import prepare
from monitor.gap.diagnose import diagnose
from monitor.gap.judge import aircheck
from monitor.gap.report.document import build_report
from monitor.gap.report.summary import summary_text
from monitor.sampling.read import read_recording
from monitor.sim.machine import load_machine

#: A seal leak of 7.5e-15 m^3/(s Pa): 1.5e-7 m^3/s at 200 bar, the loaded chamber falling
#: about 1.5 bar/s (the third plant's healthy machines: 1.1-2.0 bar/s).
LEAK = ("--fault", "piston_wear:0.0015")
#: Stops visited twice as often as the boom cycle, the lever released around them.
COVER = ("--cycle", "boom-cover")


def _signature(tmp_path: Path, name: str, *extra: str) -> aircheck.AirSignature:
    out = tmp_path / f"{name}.csv"
    argv = ["simulate", "--duration", "300", "--seed", "3", "--out", str(out), *COVER, *extra]
    assert main(argv) == 0
    machine = load_machine()
    return aircheck.signature(prepare(read_recording(out), machine), machine)


def test_oil_alone_fills_the_drained_chamber_faster_than_the_loaded_one_falls(tmp_path):
    sig = _signature(tmp_path, "leak", *LEAK)
    assert sig.readable and not sig.present
    assert sig.ratio > 2.0  # the volumes' ratio, 4.5 on the bottom stop
    assert sig.fall_bar_s == pytest.approx(1.5, rel=0.3)


def test_air_swallows_the_leak_near_tank_pressure(tmp_path):
    air = ("--effect", "entrained_air:air_fraction=0.01,polytropic_index=1.0")
    sig = _signature(tmp_path, "air", *LEAK, *air)
    assert sig.readable and sig.present
    assert sig.ratio < aircheck.RATIO
    # Over 1.8 s the leak compresses the drained chamber's 3 cm^3 of air by some 8 %, a
    # rise of 0.08 bar within the readings' noise: the fraction within a factor of two.
    assert 0.005 <= sig.air_fraction <= 0.02
    assert "free air" in sig.evidence()


def test_nothing_is_read_where_nothing_leaks_at_rest(tmp_path):
    # This simulator's own machine: the loaded chamber holds its pressure on the stop.
    sig = _signature(tmp_path, "tight")
    assert not sig.readable and not sig.present
    assert "no leak" in sig.evidence()


def test_the_third_plants_entrained_air_is_named_by_the_drained_chambers(tmp_path):
    # benchmarks/gap_third (written apart from monitor/), development seed 1's entrained
    # air (2 % isothermal free air, RodPos measured: ``generate --seed 1 --set small``:
    # s1_00).  Its healthy machines' valves leak the drained chamber full at rest, which
    # this simulator does not do; the air's fit removed little of the held-out gap and
    # the code before the check did not name it.
    sc = Scenario(
        name="air",
        seed=1000,
        effect="entrained_air",
        tolerance=0.03,
        rodpos=True,
        warmup=False,
        duration_s=300.0,
    )
    key = record(sc, tmp_path / "air.csv")
    machine = load_machine()
    diag = diagnose(read_recording(tmp_path / "air.csv"), machine, effects=("entrained_air",))
    rep = build_report(diag, machine)
    chk = rep["air_check"]
    assert rep["verdict"] == "entrained_air" and chk["air_named"] and chk["present"]
    truth = key["params"]["air_fraction_at_atm"]
    assert truth / 2 <= chk["air_fraction"] <= 2 * truth
    m = rep["mechanism"]
    assert "drained chamber" in m["decided_by"]
    if chk["verdict_without_check"] != "entrained_air":
        assert "Air: held on the end stops" in summary_text(rep)
