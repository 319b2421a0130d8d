"""The one fixed-step RK4 integrator of the simulators (the boom loop's and the whole
machine's kernels), taking the plant's functions as arguments.

A plant gives three numba functions with these signatures:

- ``rhs(y, u, prm, dy, aux)``: the state derivative into ``dy`` (``aux``: scratch outputs
  the plant may fill, such as the pump flow);
- ``project(y, prm)``: keep the state physical after a step (pressures, end stops);
- ``record(rec, r, y, u, prm, scratch, aux)``: write recorded row ``r`` from the state.

Numba compiles ``integrate`` once per plant (a function argument is part of the type), and
with ``inline="always"`` the plant's own ``integrate`` compiles to the loop it had when each
kernel wrote it out: the outputs are the same bit for bit.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from monitor.jit import jit


@jit(inline="always")
def integrate(
    rhs: Any,
    project: Any,
    record: Any,
    n_record: int,
    n_aux: int,
    y0: np.ndarray,
    inputs: np.ndarray,
    n_sub: int,
    input_dt: float,
    prm: np.ndarray,
    record_every: int,
) -> np.ndarray:
    """Classic RK4 at h = input_dt / n_sub, inputs linear between their samples.

    Returns the recorded outputs, (steps // record_every + 1, n_record): a row every
    ``record_every`` steps, the first at t=0.
    """
    n_in = inputs.shape[0]
    n_states = y0.shape[0]
    n_inputs = inputs.shape[1]
    n_steps = (n_in - 1) * n_sub
    rec = np.empty((n_steps // record_every + 1, n_record))
    y = y0.copy()
    k1 = np.empty(n_states)
    k2 = np.empty(n_states)
    k3 = np.empty(n_states)
    k4 = np.empty(n_states)
    yt = np.empty(n_states)
    aux = np.empty(max(n_aux, 1))
    u0 = np.empty(n_inputs)
    um = np.empty(n_inputs)
    u1 = np.empty(n_inputs)
    h = input_dt / n_sub
    hh = 0.5 * h
    h6 = h / 6.0
    record(rec, 0, y, inputs[0], prm, k1, aux)
    r = 1
    left = record_every
    for k in range(n_in - 1):
        a = inputs[k]
        b = inputs[k + 1]
        for j in range(n_sub):
            f0 = j / n_sub
            f1 = (j + 1) / n_sub
            fm = 0.5 * (f0 + f1)
            for i in range(n_inputs):
                d = b[i] - a[i]
                u0[i] = a[i] + f0 * d
                um[i] = a[i] + fm * d
                u1[i] = a[i] + f1 * d
            rhs(y, u0, prm, k1, aux)
            for i in range(n_states):
                yt[i] = y[i] + hh * k1[i]
            rhs(yt, um, prm, k2, aux)
            for i in range(n_states):
                yt[i] = y[i] + hh * k2[i]
            rhs(yt, um, prm, k3, aux)
            for i in range(n_states):
                yt[i] = y[i] + h * k3[i]
            rhs(yt, u1, prm, k4, aux)
            for i in range(n_states):
                y[i] += h6 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
            project(y, prm)
            left -= 1
            if left == 0:
                left = record_every
                record(rec, r, y, u1, prm, k1, aux)
                r += 1
    return rec
