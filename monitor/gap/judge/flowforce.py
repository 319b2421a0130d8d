"""A spool closed by flow forces, or an overlap: what the held flows read of the valve's
opening against the pressure drops across its edges.

A direct-operated spool is held out of centre by its solenoid against a centring spring;
each open metering edge pulls it shut with a steady flow force proportional to its opening
times its drop.  A spool sent to ``A`` then settles at ``A / (1 + k * D)``, ``D`` the drops
of the two edges it opens (``monitor.sim.laws.flow_forced``): the same command opens less
at a higher drop.  A linear simulator beside such a valve sees small flows at every command
held against a high drop and reads them as an overlap (the fifth plant's healthy machines
were named a deadband of 18-24 %).  An overlap takes a share that grows as the command
gets smaller and does not care about the drop; flow forces take a share that grows with the
drop, whatever the command.  Levels held at about the same command against different drops
tell them apart (a load pulling the pump's pressure down at a large opening, raising
against lowering).

Read by the orifice law alone, no simulation (``heldflow.edge_areas``: the open area each
held level's edges read), the law ``g * max(A / (1 + k D) - o, 0) / (1 - o)`` fitted on a
grid of ``o`` and ``k`` (the gain ``g`` in closed form), 400 resamples of the levels.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from monitor.gap.data.prepare import Prepared
from monitor.gap.data.segments import Segment
from monitor.gap.judge import heldflow as H
from monitor.sim.machine import MachineParams

#: The grids: overlaps as ``heldflow``'s (share of the stroke), flow forces in 1/bar (0.02:
#: a command halved at 50 bar across the two edges).
K_GRID_PER_BAR = np.linspace(0.0, 0.02, 41)
#: The flow forces shown: ``k`` of this (1/bar) or more in ``1 - heldflow.RULED_OUT`` of the
#: resamples (0.003: a third of the opening gone at 170 bar across the edges).  Shown on 65
#: of the fifth plant's 72 recordings of seed 276946 (0.0035-0.0125, its healthy machines
#: 0.004-0.008); on none of 240 of the third and fourth plants' and the outsider's (the
#: third plant's 12 % deadbands s730896_42, s924107_44 and slow spool s924107_40 read
#: 0.0025, 0.003 or more in 4-43 % of the resamples).
MIN_K_PER_BAR = 0.003
#: ... read over levels whose drops span this (bar) or more: at one drop a flow force is a
#: gain like any other.
MIN_SPAN_BAR = 60.0


@dataclass(frozen=True)
class FlowForce:
    """The valve's opening against the drops read from the held flows."""

    k_per_bar: float
    overlap_pct: float
    levels: int
    span_bar: float
    #: Share of resamples reading ``MIN_K_PER_BAR`` or more.
    k_share: float
    #: Share of resamples reading an overlap of ``heldflow.MIN_OVERLAP_PCT`` or more with
    #: the flow forces fitted beside it.
    overlap_share: float
    #: Squared residuals of the best overlap alone (no flow force) over the best law.
    overlap_vs_law: float

    @property
    def shown(self) -> bool:
        """Flow forces shown by levels held against drops far enough apart."""
        return self.span_bar >= MIN_SPAN_BAR and self.k_share >= 1.0 - H.RULED_OUT

    def as_dict(self) -> dict:
        return {
            "k_per_bar": round(self.k_per_bar, 4),
            "overlap_pct": round(self.overlap_pct, 1),
            "held_levels": self.levels,
            "drop_span_bar": round(self.span_bar, 0),
            "k_share": round(self.k_share, 3),
            "overlap_share": round(self.overlap_share, 3),
            "overlap_vs_law": round(self.overlap_vs_law, 3),
            "shown": self.shown,
        }


def edge_drops_bar(prep: Prepared, windows: list[tuple[int, int]], tank_bar: float) -> np.ndarray:
    """Per held level, the drops (bar) of the two edges its command opens, as the
    simulator's law takes them: P->A and B->T raising, P->B and A->T lowering."""
    m = {n: H._means(prep.meas[n], windows) for n in ("PP", "PA", "PB")}
    up = H._means(prep.cmd["SpoolCmd"], windows) > 0
    pos = np.maximum(m["PP"] - m["PA"], 0.0) + np.maximum(m["PB"] - tank_bar, 0.0)
    neg = np.maximum(m["PP"] - m["PB"], 0.0) + np.maximum(m["PA"] - tank_bar, 0.0)
    return np.where(up, pos, neg)


def read(prep: Prepared, segments: Sequence[Segment], machine: MachineParams) -> FlowForce | None:
    """The flow forces and overlap the held flows of the recording read (``machine``: the
    valve's gain, the cylinder's areas); None with fewer than ``heldflow.MIN_LEVELS``
    levels read."""
    windows = H.held(prep.cmd["SpoolCmd"], segments)
    cmd = np.abs(H._means(prep.cmd["SpoolCmd"], windows)) / 100.0
    area = H.edge_areas(prep, windows, machine)
    drops = edge_drops_bar(prep, windows, machine.valve.tank_pa / 1e5)
    ok = np.isfinite(area + drops)
    if ok.sum() < H.MIN_LEVELS:
        return None
    c, d, a = cmd[ok], drops[ok], area[ok]
    f, o, k = curves(c, d)
    best = H._law(f, a)[0]
    rng = np.random.default_rng(0)
    draws = np.empty((H.RESAMPLES, 2))
    for i in range(H.RESAMPLES):
        pick = rng.integers(0, len(a), len(a))
        j = H._law(f[:, pick], a[pick])[0]
        draws[i] = o[j], k[j]
    only_overlap = H._law(f, a, k == 0.0)[1]
    return FlowForce(
        float(k[best]),
        100.0 * float(o[best]),
        int(ok.sum()),
        float(d.max() - d.min()),
        float(np.mean(draws[:, 1] >= MIN_K_PER_BAR - 1e-12)),
        float(np.mean(100.0 * draws[:, 0] >= H.MIN_OVERLAP_PCT)),
        only_overlap / max(H._law(f, a)[1], 1e-12),
    )


def opening(command: np.ndarray, drops_bar: np.ndarray, overlap: float, k: float) -> np.ndarray:
    """The open area (share of the full stroke's) at ``command`` (share of the stroke)
    against ``drops_bar``: the spool closed by the flow forces, then the overlap crossed."""
    x = np.abs(command) / (1.0 + k * drops_bar)
    return np.maximum(x - overlap, 0.0) / (1.0 - overlap)


def curves(c: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every grid law's open area at commands ``c`` and drops ``d``: rows (overlap, k)."""
    o_grid, k_grid = np.meshgrid(H.OVERLAP_GRID, K_GRID_PER_BAR, indexing="ij")
    o, k = o_grid.ravel(), k_grid.ravel()
    rows = [opening(c, d, float(a), float(b)) for a, b in zip(o, k, strict=True)]
    return np.array(rows), o, k


def line(f: dict) -> str:
    """One line: what the held flows read of the spool's opening against the drops."""
    head = (
        f"the flows at {f['held_levels']} held commands (drops {f['drop_span_bar']:.0f} bar "
        f"apart) read flow forces of {f['k_per_bar']:.4f}/bar with an overlap of "
        f"{f['overlap_pct']:.0f} % (flow forces of {MIN_K_PER_BAR:g}/bar or more in "
        f"{f['k_share']:.0%} of resamples)"
    )
    if f["shown"]:
        return head + ": the simulator's spool closes by them"
    return head + ": not shown, the spool as configured"
