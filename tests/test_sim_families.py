"""Effect families (issue 18): the new members' physics, and nothing else moved."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sim_support import at, commands

from monitor.sim import kernel as K
from monitor.sim.effects import Effect
from monitor.sim.faults import Fault
from monitor.sim.machine import load_machine
from monitor.sim.pack import pack_params
from monitor.sim.simulate import simulate

M = load_machine()
REF = Path(__file__).parent / "data" / "sim_before_families.npz"


def test_defaults_of_the_new_parameters_leave_every_trace_bit_identical():
    # Traces written by the simulator before the family parameters existed (same profile).
    ref = np.load(REF)
    cmds = commands(
        [(0.5, 2.0, 70.0), (2.0, 3.0, 0.0), (3.0, 4.5, -60.0), (5.0, 5.3, 30.0)],
        7.0,
        oil_temp_c=65.0,
    )
    for name in ("entrained_air", "oil_viscosity", "cylinder_friction", "load_variation"):
        rec = simulate(cmds, M, effects=[Effect.make(name)], seed=None)
        for sig in ("PP", "PA", "PB", "QP", "RodPosTrue"):
            assert np.array_equal(np.asarray(rec[sig], dtype=np.float64), ref[f"{name}.{sig}"]), (
                name,
                sig,
            )
