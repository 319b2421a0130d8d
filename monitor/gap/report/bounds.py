"""A tolerance at its bound is evidence, not a result: the JSON's ``calibration_bounds``.

The calibration fits the machine's tolerances (viscous friction, volumes, ...) before any
candidate.  Where one ends at the edge of its band, either the machine is outside the
tolerance its configuration assumes, or the band has taken up part of an effect that acts
through the same signature (viscous friction for a Coulomb friction or a thick oil, the
volumes for air or a soft hose).  Each such tolerance is listed with the catalogue effects
it can stand in for, and for each of them what its own fit did: each such effect is fitted
jointly with the tolerances it trades off against (``CONFOUNDED``), so its fit says where
it left the tolerance and how much of the held-out gap it removes beyond the calibrated
machine; where its fit moved the tolerance off the bound, also beyond its own tolerances
without it (``verdict.calibration_absorbed``, one held-out run each, made for the verdict
anyway).  The recording's identifiability of the pair (``identify.py``) says whether the
two can be told apart at all.
"""

from __future__ import annotations

from collections.abc import Sequence

from monitor.gap.diagnose.records import Diagnosis
from monitor.gap.fit import calibrate as cal_mod
from monitor.gap.fit.candidates import CONFOUNDED, Candidate
from monitor.gap.fit.score import gap, reduction

#: Per tolerance: the catalogue effects it can stand in for (``CONFOUNDED`` turned round).
HIDES: dict[str, tuple[str, ...]] = {
    t.name: tuple(e for e, tols in CONFOUNDED.items() if t.name in tols) for t in cal_mod.TOLERANCES
}


_SIDE = {1: "upper", -1: "lower", 0: None}


def _single(singles: Sequence[Candidate], effect: str) -> Candidate | None:
    return next((c for c in singles if len(c.effects) == 1 and c.effects[0].name == effect), None)


def _cosine(identifiability: Sequence[dict], a: str, b: str) -> float | None:
    row = next((r for r in identifiability if set(r["pair"]) == {a, b}), None)
    return None if row is None else row["cosine"]


def _hidden(diag: Diagnosis, tolerance: str, effect: str) -> dict | None:
    """What ``effect``'s own fit (``tolerance`` free in it) did with ``tolerance``."""
    c = _single(diag.ranking.singles, effect)
    if c is None:
        return None
    f1 = c.factors.get(tolerance, 1.0)
    row: dict = {
        "effect": effect,
        "with_effect_pct": round(100 * (f1 - 1), 2),
        # Where its fit left the tolerance: "upper", "lower" or null (inside the band).
        "bound_with_effect": _SIDE[cal_mod.bound_side(tolerance, f1)],
        # Against the calibrated machine (the tolerances at their bound).
        "heldout_reduction": round(float(c.heldout_reduction), 4),
    }
    a = diag.ranking.absorbed.get(c.name)
    if a is not None:
        without = gap(a.sums[0].mse(), diag.tolerances.floor)
        row["beyond_own_tolerances"] = round(reduction(without, c.heldout_gap), 4)
    cos = _cosine(diag.identifiability, effect, tolerance)
    if cos is not None:
        row["cosine"] = cos
    return row


def calibration_bounds(diag: Diagnosis) -> list[dict]:
    """Per tolerance the calibration (before the candidates) left at its bound: which bound,
    and the candidates it could be hiding with what each one's joint fit made of it."""
    out = []
    for t in cal_mod.TOLERANCES:
        f0 = diag.tolerances.factors.get(t.name, 1.0)
        side = cal_mod.bound_side(t.name, f0)
        if side == 0:
            continue
        rows = [_hidden(diag, t.name, e) for e in HIDES[t.name]]
        out.append(
            {
                "tolerance": t.name,
                "bound": _SIDE[side],
                "change_pct": round(100 * (f0 - 1), 2),
                "band_pct": round(100 * t.band, 1),
                "could_hide": list(HIDES[t.name]),
                # Those of them fitted on this recording (each with the tolerance free).
                "fits": [r for r in rows if r is not None],
            }
        )
    return out


def bound_lines(bounds: Sequence[dict]) -> list[str]:
    """The summary's lines: each bound, then what each candidate it could hide made of it."""
    if not bounds:
        return []
    lines = ["The calibration, before any candidate, left at a bound (evidence, not a result):"]
    for b in bounds:
        head = (
            f"{b['tolerance']} at its {b['bound']} bound ({b['change_pct']:+.1f} % of "
            f"+-{b['band_pct']:g} %)"
        )
        who = ", ".join(b["could_hide"]) or "no catalogue effect"
        lines.append(f"  {head}: it could be hiding {who}")
        for r in b["fits"]:
            beyond = r.get("beyond_own_tolerances", r["heldout_reduction"])
            side = r["bound_with_effect"]
            where = f"at its {side} bound" if side else "inside its band"
            cos = f"; signatures' cosine {r['cosine']:+.2f}" if "cosine" in r else ""
            tol = f"{b['tolerance']} {r['with_effect_pct']:+.1f} % ({where})"
            lines.append(
                f"    {r['effect']}: fitted with it, {tol}; removes {100 * beyond:.0f} % of "
                f"the held-out gap the tolerances leave{cos}"
            )
    return lines
