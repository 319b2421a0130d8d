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
moving start) differs.  The samples left out are those of both readings, for every
candidate and the calibrated nominal alike (``without_arrivals_of``, from a first QP fit
before any candidate is scored): near an arrival either rod path is uncertain.  So every
candidate's residual is taken on the same samples of the same readings, and what a QP
hypothesis gains over the others is what its rod path explains.

Pressure calibrations are not reread here: their offsets (up to 20 bar) are within the
stall and hold thresholds' margins (``rodflow.HOLD_OFF_BALANCE`` counts them), and their
start states are already read through the inverse (``predict``).  With RodPos measured
the rod path is read, not integrated: nothing to reread.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from monitor.gap.data.prepare import Prepared
from monitor.gap.data.rodflow import rod_from_flow
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


def _rod_path(
    prep: Prepared, effect: Effect, machine: MachineParams
) -> tuple[np.ndarray, np.ndarray] | None:
    """The rod path (mm) integrated from QP read through ``effect``'s inverse, and its
    arrivals on a stop (``rodflow.arrivals``); None if ``effect`` does not reread."""
    if not rereads(prep, effect):
        return None
    m = prep.meas
    q_lpm = true_flow_lpm(m["QP"], effect)
    return rod_from_flow(prep.cmd["SpoolCmd"], m["PP"], m["PA"], m["PB"], q_lpm, machine)


def reread(prep: Prepared, effect: Effect, machine: MachineParams) -> Prepared | None:
    """``prep`` with its rod path integrated from QP read through ``effect``'s inverse
    (``machine``: the one ``prepare`` was given); None when ``effect`` does not change
    how ``prep`` is read (``rereads``).  Everything compared stays as it was, the samples
    left out included (module docstring: why that keeps the comparison fair)."""
    path = _rod_path(prep, effect, machine)
    return None if path is None else replace(prep, rod_mm=path[0])


def without_arrivals_of(prep: Prepared, effect: Effect, machine: MachineParams) -> Prepared:
    """``prep`` with the rod's arrivals on a stop that the reading through ``effect``
    finds left out of the comparison as well (``prep`` itself if ``effect`` does not
    reread).  Applied to every candidate alike: near an arrival either rod path is tens
    of milliseconds off (``rodflow.arrivals``), and a stall the offset hid is one the
    prepared recording never left out (its pressure steps outweighed the rest of the
    segment and bent the tolerances: viscous friction to +30 %)."""
    path = _rod_path(prep, effect, machine)
    if path is None or prep.unscored is None:
        return prep
    return replace(prep, unscored=prep.unscored | path[1])
