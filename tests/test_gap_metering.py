"""A valve deadband told from a progressive (notch-metered) valve (``judge/heldflow.py``'s
``metering``, ``diagnose/deadband.py``'s ``check_metering``), and the metering curve's shape
as a calibration tolerance (``fit/calibrate.py``'s ``valve_metering``).

Expected values by hand.  V notches over the first ``n`` of the stroke open an area growing
with the square of the opening, then the land opens linearly; joined with one slope, the
area at the notch's end is ``n / (2 - n)`` of full stroke: with ``n = 0.5`` a third at half
the stroke, ``(1/3) (A / 0.5)^2`` below it (1/12 at 25 %, 0.0533 at 20 %, 0.0085 at 8 %).
An overlap ``o`` opens ``(A - o) / (1 - o)``: nothing at 8 % under 10 %, 0.111 at 20 %.
At a held command the orifice law gives the open area as the flow over ``kv sqrt(dp)``.
"""

from __future__ import annotations

import numpy as np
import pytest

from monitor.gap.data.prepare import prepare
from monitor.gap.data.segments import make_segments
from monitor.gap.diagnose.pipeline import diagnose
from monitor.gap.fit import calibrate
from monitor.gap.judge import heldflow
from monitor.gap.report.document import build_report
from monitor.io.recording import Recording
from monitor.sim.cycles import make_cycle
from monitor.sim.effects import Effect
from monitor.sim.laws import metering as _metering
from monitor.sim.machine import load_machine
from monitor.sim.simulate import simulate
from tests.held_levels import held_levels

#: The law as Python (no compile): the kernel's own.
metering = _metering.py_func
M = load_machine()
NOTCHED = M.with_changes(notch_share=0.5)
#: Held levels (% stroke) of the staircase, each held 1.4 s out of a centred spool, both ways.
LEVELS = (8, 12, 16, 20, 25, 30, 40, 55)


def test_the_notches_law_by_hand():
    assert metering(0.5, 0.5) == pytest.approx(1 / 3)
    assert metering(0.25, 0.5) == pytest.approx(1 / 12)
    assert metering(0.75, 0.5) == pytest.approx(1 / 3 + 0.25 * (2 / 3) / 0.5)
    assert metering(1.0, 0.5) == pytest.approx(1.0)
    # One slope where the notches end: 2 (1/3) / 0.5 on both sides.
    h = 1e-6
    assert (metering(0.5, 0.5) - metering(0.5 - h, 0.5)) / h == pytest.approx(4 / 3, rel=1e-4)
    assert (metering(0.5 + h, 0.5) - metering(0.5, 0.5)) / h == pytest.approx(4 / 3, rel=1e-4)
    # The reader's twin: the overlap crossed first, then the notches.
    c = np.linspace(0.0, 1.0, 41)
    twin = heldflow.open_area(c, 0.1, 0.5)
    assert twin == pytest.approx([metering(max(x - 0.1, 0.0) / 0.9, 0.5) for x in c])


def _stairs() -> Recording:
    return held_levels(LEVELS)


@pytest.fixture(scope="module")
def stairs():
    cmd = _stairs()

    def read(machine, overlap_pct: float = 0.0):
        effects = [Effect.make("valve_deadband", overlap_pct=overlap_pct)] if overlap_pct else []
        prep = prepare(simulate(cmd, machine, effects=effects, seed=6), M)
        return heldflow.metering(prep, make_segments(prep), M)

    return {
        "notched": read(NOTCHED),
        "overlap": read(M, 10.0),
        "both": read(NOTCHED, 6.0),
    }


def _area_at(read: heldflow.Metering, command_pct: float) -> float:
    return float(np.mean([a for c, a in read.points if abs(abs(c) - command_pct) < 0.5]))


def test_an_overlap_passes_nothing_below_it_notches_a_small_growing_flow(stairs):
    notched, overlap = stairs["notched"], stairs["overlap"]
    assert notched is not None and overlap is not None
    assert notched.near_centre >= 10 and overlap.near_centre >= 10
    # The open areas the orifice law reads at the held commands, as by hand.
    assert _area_at(notched, 8) == pytest.approx((1 / 3) * 0.16**2, abs=0.002)
    assert _area_at(notched, 20) == pytest.approx((1 / 3) * 0.4**2, abs=0.003)
    assert _area_at(overlap, 8) == pytest.approx(0.0, abs=0.002)
    assert _area_at(overlap, 20) == pytest.approx(10 / 90, abs=0.005)
    # The notched valve reads no overlap (its notches at 50 %), the overlapped one 10 %.
    assert notched.overlap_pct <= 1.0 and notched.notch_pct == pytest.approx(50, abs=4)
    assert notched.overlap_share <= 0.05 and notched.overlap_vs_notch > 10
    assert notched.notch_share >= 0.95 and notched.progressive
    assert overlap.overlap_pct == pytest.approx(10, abs=1) and overlap.notch_pct <= 4
    assert overlap.overlap_share >= 0.95 and overlap.overlap_vs_notch < 0.1
    assert not overlap.progressive


def test_an_overlap_on_a_notched_valve_still_reads_as_an_overlap(stairs):
    both = stairs["both"]
    assert both is not None
    assert both.overlap_pct == pytest.approx(6, abs=1)
    assert both.overlap_share >= 0.95 and not both.progressive


def test_the_metering_tolerance_is_added_and_only_upwards():
    t = calibrate.BY_NAME["valve_metering"]
    assert (t.knob().low, t.knob().high) == (1.0, 1.0 + t.band)
    m = calibrate.apply(M, {"valve_metering": 1.3})
    assert m.valve.notch_share == pytest.approx(0.3)
    assert calibrate.describe(M, {"valve_metering": 1.3})["valve_metering"]["value"] == 0.3
    # Given back: the calibration took notches over 13 % of the stroke, the effect's fit 3 %.
    assert calibrate.gave_back("valve_metering", 1.13, 1.03)
    assert not calibrate.gave_back("valve_metering", 1.5, 1.45)
    assert not calibrate.gave_back("valve_metering", 1.03, 1.0)  # too little was taken


def _diagnosed(machine, overlap_pct: float = 0.0, stairs: bool = False) -> dict:
    cmd = _stairs() if stairs else make_cycle("boom", 60.0, 7)
    effects = [Effect.make("valve_deadband", overlap_pct=overlap_pct)] if overlap_pct else []
    rec = simulate(cmd, machine, effects=effects, seed=7)
    return build_report(diagnose(rec, M, effects=("valve_deadband",)), M)


def test_a_healthy_notched_valve_is_calibrated_away_not_a_deadband():
    # Main named this machine a deadband: a linear simulator beside notches over half
    # the stroke.  The held flows show the notches and rule out an overlap, so the
    # calibration takes the notches up (+50 % of the stroke) and nothing is left to name.
    rep = _diagnosed(NOTCHED, stairs=True)
    assert rep["verdict"] == "none"
    assert rep["calibrated"]["valve_metering"]["change_pct"] == pytest.approx(50, abs=5)
    held = rep["metering_check"]["held_flows"]
    assert held["overlap_pct"] <= 1.0 and held["notch_share"] >= 0.95


@pytest.mark.parametrize("overlap_pct", [6.0, 10.0])
def test_a_deadband_on_a_linear_valve_is_still_named(overlap_pct):
    # The boom cycle holds no command near centre: the held flows cannot rule out an
    # overlap, the calibration keeps the valve linear (notches would take up part of it:
    # over 13 % of the stroke under a 6 % overlap) and the deadband is named as before.
    rep = _diagnosed(M, overlap_pct)
    assert rep["verdict"] == "valve_deadband"
    assert rep["params"]["overlap_pct"]["value"] == pytest.approx(overlap_pct, abs=1)
    assert rep["calibrated"]["valve_metering"]["change_pct"] == 0.0
