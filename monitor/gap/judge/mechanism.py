"""Mechanism first, cause second: where the physics departs from the simulator (pump
leakage, rod friction, a sensor's dynamics, ...), then the causes that would make it, with
the evidence that separated them or the recording that would.

Built from the verdict's own keys (``verdict``, ``member``, ``ranking``, ``suggestion``,
``calibrated``, and the checks ``cause_check``, ``lag_check``, ``sensor_check``,
``absorbed``, ``identifiability``): the JSON's ``mechanism``, an addition that changes none
of them.
"""

from __future__ import annotations

from dataclasses import dataclass

from monitor.gap.fit.candidates import CONFOUNDED
from monitor.gap.judge.delays import APART_MS, PRESSURES, machine_late, shared, split


@dataclass(frozen=True)
class Mechanism:
    """Where the physics departs, and what can make it depart that way."""

    name: str
    where: str
    #: The catalogue effects (and tolerances) that act through this mechanism.
    causes: tuple[str, ...]
    #: A recording that separates the causes when this one cannot.
    separating_recording: str


_COMPLIANCE = Mechanism(
    "compliance",
    "oil volumes and lines: pressures build and fall slower than the modelled oil allows",
    ("entrained_air", "hose_compliance", "volumes"),
    "pressure steps at several pressure levels (air stiffens with pressure, hoses and "
    "volumes much less)",
)
_SENSOR = Mechanism(
    "sensor dynamics",
    "the pressure and flow readings, not the machine: they read late",
    ("sensor_lag", "spool_dynamics", "pump_control_dynamics", "hose_compliance"),
    "a recording with the engine speed varying (a sensor reads its ripple late, the "
    "machine does not) and RodPos measured (the rod moves on time under a sensor lag)",
)
_FRICTION = Mechanism(
    "rod friction",
    "the cylinder: a force against the rod's motion at reversals and breakaway",
    ("cylinder_friction", "oil_viscosity", "viscous_friction"),
    "slow moves with reversals (Coulomb friction acts at any speed, viscous with speed)",
)
#: Per catalogue effect.
BY_EFFECT: dict[str, Mechanism] = {
    "entrained_air": _COMPLIANCE,
    "hose_compliance": _COMPLIANCE,
    "sensor_lag": _SENSOR,
    "cylinder_friction": _FRICTION,
    "oil_viscosity": Mechanism(
        "leakage",
        "internal leakage that follows the oil's viscosity (pump, piston seal, valve)",
        ("oil_viscosity", "wear"),
        "a warm-up run (oil from about 20 to 50 degC): a viscous leak follows the "
        "temperature, a worn part's does not",
    ),
    "spool_dynamics": Mechanism(
        "valve spool response",
        "the valve: the spool follows its command late",
        ("spool_dynamics", "sensor_lag"),
        "spool steps with RodPos measured (a slow spool moves the rod late too)",
    ),
    "valve_deadband": Mechanism(
        "valve metering near centre",
        "the valve: no flow until the spool opens past an overlap",
        ("valve_deadband", "valve_gain"),
        "slow spool ramps through centre",
    ),
    "pump_control_dynamics": Mechanism(
        "pump flow response",
        "the pump: its flow follows the displacement command late",
        ("pump_control_dynamics", "sensor_lag"),
        "pump displacement steps at a steady engine speed",
    ),
    "load_variation": Mechanism(
        "load force",
        "the load on the rod changes with its position",
        ("load_variation", "gravity_load"),
        "holds at several rod positions",
    ),
    "sensor_calibration": Mechanism(
        "sensor reading",
        "one sensor's gain or offset, not the machine",
        ("sensor_calibration",),
        "a reference gauge on the signal",
    ),
}
#: For ``unexplained``: the suggestion's first term kind.
BY_TERM: dict[str, str] = {
    "leakage": "leakage",
    "force_velocity": "rod force with speed",
    "force_sign": "rod friction",
    "force_position": "load force",
    "force_periodic": "periodic force on the rod",
    "valve_setting": "valve flow gain",
    "pump_setting": "pump setting",
}


def describe(report: dict) -> dict | None:
    """The JSON's ``mechanism`` for a finished ``report`` (None for ``none``)."""
    verdict = report["verdict"]
    if verdict == "none":
        return None
    bounds = _bounds(report.get("calibrated") or {})
    if verdict == "unexplained":
        return _unexplained(report, bounds)
    m = BY_EFFECT[verdict]
    name, where = m.name, m.where
    chk = report.get("cause_check") if verdict == "oil_viscosity" else None
    if chk:
        name = chk["mechanism"]
    if verdict in ("sensor_calibration", "sensor_lag"):
        sig = _sensor_signal(report)
        name = f"sensor reading on {sig}" if sig else name
    decided, separated = _decided_by(report, verdict)
    out = {
        "name": name,
        "where": where,
        "cause": verdict,
        "causes": _causes(report, m),
        "decided_by": decided,
        "separating_recording": None if separated else m.separating_recording,
        "bounds": bounds,
    }
    if verdict in TIMED:
        out["timing"] = timing(report.get("delays_ms") or {})
    if chk:
        out.update(_leak_causes(chk))
    return out


def _leak_separating(chk: dict) -> str:
    """The recording that would decide a leak's cause: a warm-up, or a wider one than this
    recording's when it had one and the two laws still fit alike."""
    text = BY_EFFECT["oil_viscosity"].separating_recording
    span = chk.get("oil_temp_span_c") or 0.0
    if chk.get("flat_better_share") is None:
        return text
    wider = f"a warm-up over a wider oil temperature span than this recording's {span:.0f} degC"
    return f"{wider}; {text}"


def _leak_causes(chk: dict) -> dict:
    """A leak's mechanism keys from its oil-temperature check (``diagnose/cause.py``):
    the path, both causes with their laws and what the check made of each (the evidence
    in ``decided_by``), and whether the recording settled the cause."""
    return {
        "signal": chk["signal"],
        "causes": chk.get("causes", []),
        "cause_decided": chk["cause"] is not None,
    }


#: Verdicts whose look-alikes differ in which readings are late.
TIMED = ("sensor_lag", "spool_dynamics", "pump_control_dynamics", "hose_compliance")


def timing(delays: dict) -> str:
    """One line: which readings are late against the simulator, and what that says (a lag
    the rod does not share is a sensor's; one it shares is the machine's)."""
    if not delays:
        return "no timing measured"
    p, q, rod = shared(delays, PRESSURES), delays.get("QP"), delays.get("RodVel")
    parts = [f"{k} {v:+.0f} ms" for k, v in delays.items() if v is not None]
    line = "readings against the calibrated simulator: " + ", ".join(parts)
    if p is None:
        return line
    sp = split(delays)
    if sp is not None and sp.some_late:
        ref = "the rod moves" if sp.reference == "rod" else "the other readings"
        return line + (
            f"; {', '.join(sp.late)} read {APART_MS:.0f} ms or more later than {ref}: a lag "
            "of those readings (sensor), not of the machine"
        )
    if rod is None:
        return line + " (no rod reading: a sensor's lag and the machine's look alike)"
    if p - rod >= APART_MS:
        return line + (
            f"; the pressures read {p - rod:.0f} ms later than the rod moves: a lag of the "
            "readings (sensor), not of the machine"
        )
    if machine_late(delays):
        return line + "; the rod is as late as the pressures: the machine itself is late"
    if q is not None and p - q >= APART_MS:
        return line + "; the pressures read later than the flow"
    return line


def _unexplained(report: dict, bounds: list[str]) -> dict | None:
    sugg = report.get("suggestion") or []
    if not sugg:
        return {
            "name": None,
            "where": "no catalogue effect and no correction term explains the gap",
            "cause": None,
            "causes": [],
            "decided_by": "no term removes enough of the held-out gap",
            "separating_recording": None,
            "bounds": bounds,
        }
    first = sugg[0]
    name = BY_TERM.get(first["term"], first["term"])
    if first["term"] not in BY_TERM:  # a sensor term: gain, offset or delay of one signal
        kind = first["term"].removeprefix("sensor_").replace("_", " ")
        name = f"sensor {kind} on {first['signal']}"
    elif first["term"] == "leakage":
        name = f"leakage {first['signal']}"
    cause = first.get("cause")
    chk: dict = report.get("cause_check") or {}
    leak = bool(chk) and cause in ("wear", "undecided")
    if leak:
        # Mechanism first: the leak's path (pump leakage), as an oil_viscosity verdict
        # would name it; the cause (wear, or undecided between wear and viscosity) second.
        name = chk["mechanism"]
    decided = (
        chk["evidence"]
        if leak
        else (
            f"the correction term that removes the most of the held-out gap "
            f"({100 * first['heldout_reduction']:.0f} %): {first['description']}"
        )
    )
    out = {
        "name": name,
        "where": first["description"],
        "cause": cause or "outside the catalogue",
        "causes": [],
        "decided_by": decided,
        # A leak of undecided cause: the recording that would decide it.
        "separating_recording": _leak_separating(chk) if leak and cause == "undecided" else None,
        "bounds": bounds,
    }
    if leak:
        out.update(_leak_causes(chk))
    return out


def _sensor_signal(report: dict) -> str | None:
    params = report.get("params") or {}
    lagged = (params.get("sensor_lag") or {}).get("signals")
    if lagged:
        return ", ".join(lagged)
    keys = params.get("sensor_calibration") or {}
    return next((k.split("_")[0] for k in keys), None)


def _causes(report: dict, m: Mechanism) -> list[dict]:
    """The mechanism's catalogue causes with their held-out scores (best first): how far
    the named one stood apart from the others on this recording."""
    rows = {r["effect"]: r for r in report.get("ranking") or []}
    out = [
        {
            "cause": c,
            "heldout_reduction": rows[c]["heldout_reduction"],
            "criterion": rows[c]["criterion"],
        }
        for c in m.causes
        if c in rows
    ]
    return sorted(out, key=lambda r: r["criterion"])


def _decided_by(report: dict, verdict: str) -> tuple[str, bool]:
    """What separated the named cause from its look-alikes, and whether it was a check
    of its own (False: the held-out criterion alone, which a look-alike may come close to)."""
    chk = report.get("cause_check")
    if verdict == "oil_viscosity" and chk:
        return chk["evidence"], chk["cause"] is not None
    fc = report.get("friction_check")
    if (
        verdict == "cylinder_friction"
        and fc
        and fc.get("friction_named")
        and (fc.get("separated") or fc["verdict_without_check"] != verdict)
    ):
        # The rod's force balance: Coulomb friction beside viscous friction held in its band.
        # Separated (viscous friction held in its band or free): no other recording needed.
        return fc["evidence"], bool(fc.get("separated"))
    ac = report.get("air_check")
    if verdict == "entrained_air" and ac and ac.get("present"):
        # The drained chambers on the stops: soft near tank pressure, stiff loaded.
        return ac["evidence"], True
    lc = report.get("load_check")
    if verdict == "load_variation" and lc and lc.get("present"):
        # The rod's holds: a load that changes with the pose, which no base mismatch enters.
        return lc["evidence"], True
    tm = report.get("timing") or {}
    if (tm.get("sensor_lag_on_late") or {}).get("named"):
        # Some readings late, the rod and the others on time: a sensor's dynamics.
        return tm["decided_by"], True
    tc = report.get("timing_check")
    if tc is not None:
        # The rod's timing decided between a sensor's lag and the machine's.
        return timing(tc["delays_ms"]), True
    lag = report.get("lag_check")
    if verdict == "sensor_lag" and lag:
        return f"the readings follow the engine's speed ripple late ({lag.get('readings')})", True
    sc = report.get("sensor_check")
    if verdict == "sensor_calibration" and sc:
        plant = "a sensor error moves one signal only: no plant term explains more"
        return (f"{sc['evidence']}; {plant}" if sc.get("evidence") else plant), True
    ab = report.get("absorbed")
    if ab:
        tols = ", ".join(
            f"{t} {v['calibration_pct']:+.0f} % -> {v['with_effect_pct']:+.0f} %"
            for t, v in ab["tolerances"].items()
        )
        return (
            f"the calibration had taken a tolerance to its bound in the effect's place "
            f"({tols}); judged against its own tolerances it removes "
            f"{100 * ab['heldout_reduction']:.0f} % of the held-out gap",
            False,
        )
    return _margin(report, verdict), False


def _margin(report: dict, verdict: str) -> str:
    rows = report.get("ranking") or []
    best = next((r for r in rows if r["effect"] == verdict), None)
    others = [r for r in rows if r["effect"] != verdict and "+" not in r["effect"]]
    if best is None or not others:
        return "the held-out criterion"
    runner = min(others, key=lambda r: r["criterion"])
    return (
        f"the held-out criterion: {verdict} removes {100 * best['heldout_reduction']:.0f} % "
        f"of the held-out gap, the next ({runner['effect']}) "
        f"{100 * runner['heldout_reduction']:.0f} % (criterion "
        f"{runner['criterion'] - best['criterion']:+.1f} behind)"
    )


def _bounds(calibrated: dict) -> list[str]:
    """A tolerance at its bound is evidence, not a result: the effects it can stand in for."""
    by_tol: dict[str, list[str]] = {}
    for effect, tols in CONFOUNDED.items():
        for t in tols:
            by_tol.setdefault(t, []).append(effect)
    out = []
    for t, row in calibrated.items():
        if row.get("at_bound"):
            who = ", ".join(by_tol.get(t, [])) or "no catalogue effect"
            out.append(
                f"{t} at its {row['change_pct']:+.0f} % bound: the machine is outside its "
                f"tolerance, or the band stands in for an effect ({who})"
            )
    return out
