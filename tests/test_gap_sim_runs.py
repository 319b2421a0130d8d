"""How the sim-to-real tool runs the simulator: packed once per segment set, and the fits'
coarser step, each against the plain simulator path."""

from __future__ import annotations

import numpy as np
import pytest

from monitor.gap.data.prepare import prepare
from monitor.gap.data.segments import make_segments, split
from monitor.gap.diagnose import FIT_STEP_FACTOR, HELDOUT_STEP_FACTOR
from monitor.gap.fit import calibrate as cal_mod
from monitor.gap.fit.predict import SegmentPlant, _measured_start, _start_state, predict
from monitor.gap.fit.score import compared, noise_floor
from monitor.io.recording import Recording
from monitor.sim.cycles import make_cycle
from monitor.sim.effects import Effect
from monitor.sim.machine import load_machine
from monitor.sim.pack import pack_params
from monitor.sim.simulate import run_plant, simulate

M = load_machine()


@pytest.fixture(scope="module")
def recording():
    """A 60 s boom recording with sensor noise, its preparation and segments."""
    rec = simulate(make_cycle("boom", 60.0, 5), M, seed=2)
    prep = prepare(rec, M)
    return prep, make_segments(prep)


@pytest.mark.parametrize(
    "effects",
    [
        (Effect.make("oil_viscosity", nu40_cst=68.0, nu100_cst=8.7),),
        (),
        (Effect.make("oil_viscosity"), Effect.make("cylinder_friction")),
    ],
)
def test_segment_plant_equals_running_each_segment_through_run_plant(recording, effects):
    prep, segments = recording
    plant = SegmentPlant(prep, segments[:4])
    # A viscosity, then none, then another one: the cached packings must follow.
    for fx in ((Effect.make("oil_viscosity", nu40_cst=32.0, nu100_cst=5.4),), effects):
        traces = plant.traces(M, fx)
    prm = pack_params(M, effects)
    for seg, tr in zip(segments[:4], traces, strict=True):
        rows = slice(seg.start, seg.stop + 1)
        cmds = Recording(prep.t[rows], {n: v[rows] for n, v in prep.cmd.items()})
        y0 = _start_state(_measured_start(prep, seg), M, prm)
        ref = run_plant(cmds, M, effects=effects, state0=y0)
        np.testing.assert_array_equal(tr.t_s, ref.t_s)
        for name in ("pp_pa", "pa_pa", "pb_pa", "qp_m3_s", "rod_pos_m"):
            np.testing.assert_allclose(getattr(tr, name), getattr(ref, name), rtol=1e-12)


@pytest.mark.parametrize("factor", sorted({FIT_STEP_FACTOR, HELDOUT_STEP_FACTOR}))
def test_the_fits_coarser_step_stays_well_inside_the_sensor_noise(factor):
    """At the stiffest corner of the tolerance bands (smallest volumes and mass, the fastest
    pressure dynamics, least damping) the fits' and the held-out scores' step departs from
    the configured one by a small fraction of the noise a perfect simulator leaves (a 500 us
    step: most of it), on the held-out segments the scores are taken on."""
    fx = [Effect.make("cylinder_friction", coulomb_n=400.0)]
    rec = simulate(make_cycle("boom", 300.0, 3), M, effects=fx, seed=3)
    prep = prepare(rec, M)
    _, held = split(make_segments(prep))
    stiff = cal_mod.apply(
        M, {"volumes": 0.85, "mass": 0.85, "valve_gain": 1.1, "viscous_friction": 0.7}
    )
    coarse = stiff.with_changes(step_s=stiff.solver.step_s * factor)
    assert coarse.solver.step_s > M.solver.step_s
    ref = predict(prep, held, stiff, ())
    got = predict(prep, held, coarse, ())
    floor = noise_floor(prep)
    for i, name in enumerate(compared(prep)):
        diff = np.nanmean(((got[name] - ref[name]) / prep.scale[name]) ** 2)
        assert diff < 0.1 * floor[i], name
