"""What to do: one action text per fault name and per sensor check (the fleet page and the
docs render this table; docs/how-to/fleet.md is generated from it).

Fault names are those of the isolation (``monitor.sim.faults``); sensor checks those of
the plausibility checks (``monitor.detection.plausibility``) and ``stale`` (frames stopped).
"""

from __future__ import annotations

from monitor.signals import ROD_POS, SIGNALS

#: fault name -> (what is suspected, what to do)
FAULT_ACTIONS: dict[str, tuple[str, str]] = {
    "piston_wear": (
        "piston seal suspected",
        "inspect the boom cylinder for internal leakage (drift test: load held "
        "with the valve centred, rod creeping)",
    ),
    "spool_wear": (
        "worn valve spool suspected",
        "inspect the boom section of the directional valve for worn metering "
        "edges (leakage across the lands at centre)",
    ),
    "spool_stroke": (
        "spool stroke limited",
        "check the boom spool's pilot pressure, solenoid current and end "
        "stops: the spool does not reach full stroke",
    ),
    "pump_wear": (
        "worn pump suspected",
        "check the shared pump's case drain flow and its load-sensing margin at full flow: "
        "it falls short of its margin with every section, the regulator making up a leak",
    ),
    "unknown": (
        "hydraulic fault, not isolated",
        "the loop no longer behaves as commissioned; look at the signals around "
        "the alarm, then check cylinder, valve and pump",
    ),
}

#: sensor check -> (what is wrong, read after the signal's name: "QP frozen"; what to do)
SENSOR_ACTIONS: dict[str, tuple[str, str]] = {
    "frozen": (
        "frozen",
        "check the sensor and its wiring; its reading no longer changes while the engine runs",
    ),
    "stuck": ("stuck", "check the sensor: it no longer follows the loop while the machine moves"),
    "signal_range": (
        "out of range",
        "check the sensor, its supply and wiring (open or short circuit)",
    ),
    "pump_below_port": (
        "offset (reads above the pump)",
        "calibrate or replace the pressure "
        "sensor: a port reads above the pump while the valve feeds it",
    ),
    "rest_offset": (
        "offset at rest",
        "calibrate or replace the sensor: it reads away from tank pressure with the engine off",
    ),
    "stale": (
        "silent (no frames)",
        "check the sensor's CAN node, connector and bus wiring: its frames stopped",
    ),
    "unknown": ("faulty", "check the machine's sensors and CAN wiring"),
}

#: The machine states of the fleet table, with what to do when nothing is named.
STATE_ACTIONS: dict[str, str] = {
    "healthy": "nothing to do",
    "wearing": "the typical residual has doubled since commissioning: plan an inspection",
    "not_judged": "no verdict: see why the log was not judged (engine off, warm-up, ...)",
    "error": "the log could not be read: check the uploader and the file",
}


def fault_action(name: str | None) -> tuple[str, str]:
    """(what is suspected, what to do) for a fault name (an unnamed or new name: unknown's)."""
    return FAULT_ACTIONS.get(name or "unknown", FAULT_ACTIONS["unknown"])


def sensor_action(check: str | None) -> tuple[str, str]:
    """(what is wrong, what to do) for a sensor check (none or a new one: unknown's)."""
    return SENSOR_ACTIONS.get(check or "unknown", SENSOR_ACTIONS["unknown"])


def sensor_label(signal: str, check: str | None) -> str:
    """What the page says of a sensor finding: ``QP frozen``, ``PA silent (no frames)``."""
    who = "a sensor (not named)" if signal == "unknown" else signal
    return f"{who} {sensor_action(check)[0]}"


#: The contract's signals by name, for ``signal_meaning``.
_KNOWN = {s.name: s for s in (*SIGNALS, ROD_POS)}


def signal_meaning(signal: str) -> str:
    """What a sensor finding's signal measures, for a reader who does not know the names:
    ``QP: pump outlet flow (L/min)``; a loop's signal (``Stick_QP``) by its base name; ""
    for a name the contract does not hold."""
    s = _KNOWN.get(signal) or _KNOWN.get(signal.rsplit("_", 1)[-1])
    return f"{signal}: {s.description} ({s.unit})" if s else ""


def markdown_table() -> str:
    """The action table as Markdown (the docs render it)."""
    lines = ["| finding | name | the page says | what to do |", "|---|---|---|---|"]
    lines += [f"| fault | `{k}` | {a} | {b} |" for k, (a, b) in FAULT_ACTIONS.items()]
    lines += [f"| sensor check | `{k}` | {a} | {b} |" for k, (a, b) in SENSOR_ACTIONS.items()]
    return "\n".join(lines)
