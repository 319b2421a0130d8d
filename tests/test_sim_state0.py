"""Starting the plant from a measured state: a restart continues the uninterrupted run."""

from __future__ import annotations

import numpy as np
import pytest
from sim_support import commands

from monitor.errors import ConfigError
from monitor.io.recording import Recording
from monitor.sim import kernel as K
from monitor.sim.machine import load_machine
from monitor.sim.pack import measured_state, pack_params
from monitor.sim.simulate import run_plant

M = load_machine()


def _tail(cmds: Recording, start: int) -> Recording:
    return Recording(cmds.t[start:], {k: v[start:] for k, v in cmds.columns.items()})


@pytest.mark.parametrize("restart_s", [1.2, 2.5])  # mid-raise (moving) and mid-hold
def test_restart_from_the_recorded_state_reproduces_the_continuous_run(restart_s):
    cmds = commands([(0.3, 2.0, 60.0), (3.0, 4.0, -50.0)], 4.5)
    full = run_plant(cmds, M, rod_pos0_m=0.2, record_period_s=None)
    k = int(round(restart_s / 0.01))
    j = int(round(restart_s / M.solver.step_s))  # record row of the restart instant
    y0 = measured_state(
        M,
        pack_params(M),
        full.pp_pa[j],
        full.pa_pa[j],
        full.pb_pa[j],
        full.rod_pos_m[j],
        full.rod_vel_m_s[j],
        spool=cmds["SpoolCmd"][k] / 100,
    )
    part = run_plant(_tail(cmds, k), M, record_period_s=None, state0=y0)
    assert part.t_s[0] == pytest.approx(restart_s)
    n = len(part.t_s)
    # Same states, same inputs, same steps: the two runs agree to rounding.
    np.testing.assert_allclose(part.pa_pa, full.pa_pa[j : j + n], rtol=1e-7, atol=1.0)
    np.testing.assert_allclose(part.rod_pos_m, full.rod_pos_m[j : j + n], atol=1e-9)


def test_measured_state_disp_follows_the_compensator():
    # Dead-headed at 195 bar, half way through the 190-200 bar destroke: disp 0.5.
    y = measured_state(M, pack_params(M), 195e5, 50e5, 2e5, 0.1)
    assert y[K.S_DISP] == pytest.approx(0.5)
    assert y[K.S_V] == 0.0


def test_a_state_of_the_wrong_size_is_refused():
    with pytest.raises(ConfigError, match="state0"):
        run_plant(commands([], 0.5), M, state0=np.zeros(3))
