"""A spool closed by steady flow forces (``monitor.sim.laws.flow_forced``), read from the
held flows (``judge/flowforce.py``) and given to the simulator where they show it
(``diagnose/fitting.py``'s ``valve_law``), so that a deadband is named only where an
overlap shows beside them.

Expected values by hand.  A direct-operated spool sent to ``A`` settles where the spring's
force ``ks (A - x)`` equals the flow forces ``ks k x D`` of its two open edges (``D`` their
drops): ``x = A / (1 + k D)``.  At 0.3 with 120 bar across the edges and ``k`` 0.005/bar,
``0.3 / 1.6 = 0.1875``.  The valve's rated flow is the flow at its rated drop (10 bar per
edge) with the flow forces that drop sets, so the edge's own coefficient is ``1 + k 20 bar``
times the rated one.  At a held command the orifice law gives the open area as the flow over
``kv sqrt(dp)``.
"""

from __future__ import annotations

import numpy as np
import pytest

from monitor.errors import ConfigError
from monitor.gap.data.prepare import prepare
from monitor.gap.data.segments import make_segments
from monitor.gap.diagnose.pipeline import diagnose
from monitor.gap.judge import flowforce
from monitor.gap.report.document import build_report
from monitor.io.recording import Recording
from monitor.sim import kernel as K
from monitor.sim.effects import Effect
from monitor.sim.laws import flow_forced as _flow_forced
from monitor.sim.machine import BAR, LPM, load_machine, machine_from_mapping
from monitor.sim.pack import pack_params
from monitor.sim.simulate import simulate
from tests.held_levels import held_levels

#: The law as Python (no compile): the kernel's own.
flow_forced = _flow_forced.py_func
M = load_machine()
K_PER_BAR = 0.006
FORCED = M.with_changes(flow_force=K_PER_BAR / BAR)
#: Held levels (% stroke), each held 1.4 s out of a centred spool, both ways: the small ones
#: against the compensator's pressure, the large ones at the pump's full flow (a low drop).
LEVELS = (20, 30, 45, 60, 80, 100)


def test_the_flow_forces_law_by_hand():
    k = 0.005 / BAR
    # Raising: P->A and B->T open; 100 bar + 20 bar across them.
    assert flow_forced(0.3, 150 * BAR, 50 * BAR, 20 * BAR, 0.0, k) == pytest.approx(0.1875)
    # Lowering: P->B and A->T; the same pressures give 130 + 50 bar.
    assert flow_forced(-0.3, 150 * BAR, 50 * BAR, 20 * BAR, 0.0, k) == pytest.approx(-0.3 / 1.9)
    # A drop against the flow pushes nothing; no drop, no force.
    assert flow_forced(0.3, 40 * BAR, 50 * BAR, 0.0, 0.0, k) == pytest.approx(0.3)
    assert flow_forced(0.3, 150 * BAR, 50 * BAR, 20 * BAR, 0.0, 0.0) == 0.3


def test_the_yaml_key_and_the_default_leave_the_kernel_as_it_was():
    m = machine_from_mapping({"valve": {"flow_force_per_bar": 0.005}})
    assert m.valve.flow_force == pytest.approx(0.005 / BAR)
    with pytest.raises(ConfigError, match="flow_force_per_bar"):
        machine_from_mapping({"valve": {"flow_force_per_bar": -0.1}})
    plain, forced = pack_params(M), pack_params(m)
    assert plain[K.FLOW_FORCE] == 0.0 and plain[K.KV] == M.valve.valve_kv
    # The rated flow at the rated drop, flow forces included: 1 + 0.005 * 20 bar.
    assert forced[K.KV] == pytest.approx(1.1 * M.valve.valve_kv)


def _ladder() -> Recording:
    return held_levels(LEVELS, name="ladder")


@pytest.fixture(scope="module")
def ladder():
    cmd = _ladder()

    def run(machine, overlap_pct: float = 0.0):
        effects = [Effect.make("valve_deadband", overlap_pct=overlap_pct)] if overlap_pct else []
        rec = simulate(cmd, machine, effects=effects, seed=6)
        prep = prepare(rec, M)
        return rec, flowforce.read(prep, make_segments(prep), M)

    return {
        "forced": run(FORCED),
        "forced_overlap": run(FORCED, 10.0),
        "linear": run(M),
        "overlap": run(M, 10.0),
    }


def test_the_simulated_spool_closes_by_the_flow_forces(ladder):
    # The last 0.5 s of the 45 % raise: the open area the orifice law reads there (P->A)
    # against the law by hand, from the simulated pressures.
    rec = ladder["forced"][0]
    c = rec.columns
    at = np.flatnonzero(c["SpoolCmd"] == 45.0)
    rows = at[at >= at[0] + 90][:50]
    pp, pa, pb, qp = (float(np.mean(c[n][rows])) for n in ("PP", "PA", "PB", "QP"))
    area = qp * LPM / (M.valve.valve_kv * np.sqrt((pp - pa) * BAR))
    drops = (pp - pa) + pb
    assert drops > 100.0  # the compensator's pressure across the edges
    expected = (1 + K_PER_BAR * 20) * 0.45 / (1 + K_PER_BAR * drops)
    assert area == pytest.approx(expected, rel=0.04)


def test_the_held_flows_read_flow_forces_and_an_overlap_apart(ladder):
    forced, both = ladder["forced"][1], ladder["forced_overlap"][1]
    linear, overlap = ladder["linear"][1], ladder["overlap"][1]
    assert forced is not None and both is not None and linear is not None and overlap is not None
    assert forced.span_bar >= 150
    assert forced.k_per_bar == pytest.approx(K_PER_BAR, abs=0.001)
    assert forced.overlap_pct <= 1.0 and forced.overlap_share <= 0.05 and forced.shown
    # An overlap beside them is read as one, the flow forces as before.
    assert both.k_per_bar == pytest.approx(K_PER_BAR, abs=0.001) and both.shown
    assert both.overlap_pct == pytest.approx(10, abs=1.5) and both.overlap_share >= 0.95
    # No flow forces on a linear valve, with or without an overlap: the gate stays shut.
    assert linear.k_per_bar == 0.0 and not linear.shown
    assert overlap.k_per_bar <= 0.001 and not overlap.shown


def _diagnosed(machine, overlap_pct: float = 0.0) -> dict:
    effects = [Effect.make("valve_deadband", overlap_pct=overlap_pct)] if overlap_pct else []
    rec = simulate(_ladder(), machine, effects=effects, seed=7)
    return build_report(diagnose(rec, M, effects=("valve_deadband",)), M)


def test_a_healthy_spool_closed_by_flow_forces_is_not_a_deadband():
    # Without the flow forces read (the linear simulator beside this valve) the verdict is
    # `unexplained`: the deadband fitted an overlap for the small flows at high drops but
    # not enough of the gap.  With them read from the held flows nothing is left to name.
    rep = _diagnosed(FORCED)
    assert rep["verdict"] == "none"
    check = rep["metering_check"]
    assert check["simulated_flow_force_per_bar"] == pytest.approx(K_PER_BAR, abs=0.001)
    assert check["flow_forces"]["shown"]
