"""A healthy pump slips: a leak within what a sound pump loses is a tolerance, not a finding.

A new axial piston pump delivers 95-98 % of its geometric flow at its rated pressure
(volumetric efficiency; the rest is the slip past its pistons, slippers and port plate,
laminar, ~ p / viscosity).  The simulator's pump slips not at all, so on a sensor-precise
recording a sound pump's slip reads as pump leakage: this simulator's own boom loop with a
constant 0.25 L/min per 100 bar (97.9 % at 200 bar) was ``unexplained``, pump leakage of
undecided cause, the leak removing 99 % of the held-out gap.  So a pump leakage no larger
than ``1 - VOLUMETRIC_EFFICIENCY_MIN`` of the pump's full flow at its compensator pressure,
after which the simulator is within what a tolerance calibration leaves on a healthy
machine (the same test that makes ``none`` without an effect, ``decide.not_named``), is
``none`` with the slip said; a larger one, or one that leaves a gap, keeps its verdict.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monitor.gap.fit.score import SegmentSums
from monitor.gap.judge import basemis
from monitor.gap.judge.decide import MARGINAL_RATIO, SIGNIFICANT, within_noise
from monitor.gap.judge.shrink import boot_mse
from monitor.sim.machine import BAR, MachineParams

#: The least volumetric efficiency of a sound axial piston pump at its rated pressure
#: (new pumps 95-98 %; below about 90 % one is worn out).
VOLUMETRIC_EFFICIENCY_MIN = 0.95


def full_flow_lpm(machine: MachineParams) -> float:
    """The pump's geometric flow at full displacement and nominal speed (L/min)."""
    return machine.pump.pump_disp_m3_rev * machine.pump.nominal_speed_rpm * 1e3


def rated_bar(machine: MachineParams) -> float:
    """The pressure a healthy pump's slip is judged at: where the compensator has destroked
    it fully (bar), the highest the pump holds."""
    return machine.pump.compensator_full_pa / BAR


def healthy_max_lpm_per_100bar(machine: MachineParams) -> float:
    """The largest laminar slip (L/min per 100 bar) of a pump at ``VOLUMETRIC_EFFICIENCY_MIN``
    at ``rated_bar``: 0.61 for the reference pump (11 cm^3/rev at 2200 rpm, 200 bar)."""
    lost = (1.0 - VOLUMETRIC_EFFICIENCY_MIN) * full_flow_lpm(machine)
    return lost / (rated_bar(machine) / 100.0)


def rest_is_none(
    sums: SegmentSums, smooth: SegmentSums, idx: np.ndarray, floor: np.ndarray
) -> float | None:
    """With the slip in the simulator, the confidence that what is left is what a healthy
    machine leaves (None: it is not), by ``decide.not_named``'s test: the structured part
    below the practical level (or not clearly above it), or every signal within
    ``MARGINAL_RATIO`` x the noise."""
    floor_s = basemis.smoothed_floor(floor)
    small = basemis.small_share(smooth, idx, floor_s)
    if basemis.practically_small(smooth, floor_s) or small > 1 - SIGNIFICANT:
        return small
    if within_noise(sums, floor, MARGINAL_RATIO):
        return float(np.mean(np.all(boot_mse(sums, idx) < MARGINAL_RATIO * floor, axis=1)))
    return None


@dataclass(frozen=True)
class PumpSlip:
    """A pump leakage against a healthy pump's slip."""

    #: The fitted pump leak at the recording's oil temperature (L/min per 100 bar).
    leak_lpm_per_100bar: float
    #: ``healthy_max_lpm_per_100bar`` of the configured pump.
    healthy_max_lpm_per_100bar: float
    full_flow_lpm: float
    rated_bar: float
    #: With the slip added, the confidence that the rest is a healthy machine's (None: not).
    rest_none: float | None

    @property
    def volumetric_efficiency(self) -> float:
        """The pump's volumetric efficiency at ``rated_bar`` with this leak."""
        lost = self.leak_lpm_per_100bar * self.rated_bar / 100.0
        return 1.0 - lost / self.full_flow_lpm

    @property
    def healthy(self) -> bool:
        """Within a sound pump's slip, and nothing else left."""
        return self.leak_lpm_per_100bar <= self.healthy_max_lpm_per_100bar and (
            self.rest_none is not None
        )

    def evidence(self) -> str:
        """One line: the leak as a volumetric efficiency, and what that makes of it."""
        ve = f"{100 * self.volumetric_efficiency:.1f} %"
        head = (
            f"pump leakage of {self.leak_lpm_per_100bar:.2g} L/min per 100 bar is a volumetric "
            f"efficiency of {ve} at {self.rated_bar:.0f} bar"
        )
        low = f"{100 * VOLUMETRIC_EFFICIENCY_MIN:.0f} %"
        if self.leak_lpm_per_100bar > self.healthy_max_lpm_per_100bar:
            return f"{head}, below the {low} of a sound pump: more than its slip"
        if self.rest_none is None:
            return f"{head}, a sound pump's slip, but the simulator with it still departs"
        return (
            f"{head}, a sound pump's slip ({low} or better), and with it the simulator is "
            "within what a healthy machine leaves"
        )

    def as_dict(self) -> dict:
        """The JSON's ``slip_check``."""
        return {
            "leak_lpm_per_100bar": round(self.leak_lpm_per_100bar, 4),
            "healthy_max_lpm_per_100bar": round(self.healthy_max_lpm_per_100bar, 4),
            "volumetric_efficiency": round(self.volumetric_efficiency, 4),
            "at_bar": round(self.rated_bar, 1),
            "healthy": self.healthy,
            "evidence": self.evidence(),
        }
