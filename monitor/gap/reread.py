"""The recording read through a hypothesised flow meter error: the rod path without RodPos.

Without RodPos the rod path is integrated from QP and anchored where the recording shows
the rod on an end stop (``rodflow``).  A QP gain or offset reaches both: a gain scales the
integrated stroke, and an offset hides the stalls (a stalled pump reads the offset, not
below ``rodflow.STALL_FLOW_LPM``: +3.5 L/min left 0 of 291 stall samples), so the rod is
placed wrong, the plant runs start from wrong rod positions and the pressures disagree
however the QP reading itself is corrected.  A QP hypothesis therefore reads the recording
through its inverse (``true = (reading - offset) / gain``) wherever the recording is taken
as the truth, the rod path included: one mechanism, whatever the mix of gain and offset.

Fair against the other candidates: the rereading keeps every compared reading (the raw QP
included: the hypothesis' sensor model maps the simulated flow onto it), the segments,
the calibration/held-out split, the scales, the noise floor and the samples left out of
the comparison; only the rod path the plant runs start from (position, and speed at a
moving start) differs.  So every candidate's residual is taken on the same samples of the
same readings, and what a QP hypothesis gains over the others is what its rod path
explains.

Pressure calibrations are not reread here: their offsets (up to 20 bar) are within the
stall and hold thresholds' margins (``rodflow.HOLD_OFF_BALANCE`` counts them), and their
start states are already read through the inverse (``predict``).  With RodPos measured
the rod path is read, not integrated: nothing to reread.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from monitor.gap.prepare import Prepared
from monitor.gap.rodflow import rod_from_flow
from monitor.sim.effects import Effect
from monitor.sim.machine import MachineParams

#: The calibrations a recording is reread through: the sensor the rod path is built from.
REREAD_SIGNALS = ("QP",)


def true_flow_lpm(reading_lpm: np.ndarray, effect: Effect) -> np.ndarray:
    """The flow (L/min) a QP reading stands for under ``effect`` (``reading = gain x true
    + offset``); NaN stays NaN."""
    return (np.asarray(reading_lpm, dtype=float) - effect.params["offset"]) / effect.params["gain"]


def rereads(prep: Prepared, effect: Effect) -> bool:
    """Whether ``effect`` changes how ``prep`` is read: a QP calibration without RodPos."""
    return (
        not prep.has_rodpos
        and effect.name == "sensor_calibration"
        and effect.labels["signal"] in REREAD_SIGNALS
    )


def reread(prep: Prepared, effect: Effect, machine: MachineParams) -> Prepared | None:
    """``prep`` with its rod path integrated from QP read through ``effect``'s inverse
    (``machine``: the one ``prepare`` was given); None when ``effect`` does not change
    how ``prep`` is read (``rereads``).  Everything compared stays as it was (module
    docstring: why that keeps the comparison fair)."""
    if not rereads(prep, effect):
        return None
    m = prep.meas
    rod_mm, _ = rod_from_flow(
        prep.cmd["SpoolCmd"], m["PP"], m["PA"], m["PB"], true_flow_lpm(m["QP"], effect), machine
    )
    return replace(prep, rod_mm=rod_mm)
