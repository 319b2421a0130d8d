"""The loop and machine a model was trained on, and the check that refuses it for another.

A model learns one loop of one machine: its residuals are only small on that loop's
dynamics (bore, mass, flows).  The model file's header key ``machine`` (optional, so files
from before it still load, as "unknown") records the loop's name and, when the training
config names the machine (its ``machine:`` simulator YAML), the machine's cylinder, load,
pump and valve.  The flows and pressures the model saw are its training envelope
(``validity``).  ``check_model_for_loop`` compares them with the loop a config gives the
model: another loop's name, another machine (a parameter more than ``MACHINE_TOLERANCE``
off) or training data the configured machine cannot produce (more than
``CAPABILITY_MARGIN`` times its pump's flow or its relief pressure) is a ``ModelFileError``
naming both.

The card also records the machine a model was commissioned on (``id``: the config's
``machine_id`` when it was trained; ``REFERENCE_MACHINE`` for the shipped model), and
``reference_reason`` is the one rule, offline, in the daemon and in the fleet, for whether a
model judges its own machine or another one (a reference model, whose hydraulic alarms are
then withheld: ``monitor.detection.decision``).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

from monitor.errors import ModelFileError
from monitor.model.envelope import Envelope
from monitor.sim.machine import BAR, LPM, MachineParams

log = logging.getLogger("monitor")

#: Header name -> (MachineParams parameter, factor SI -> header unit, label, unit).
MACHINE_KEYS: dict[str, tuple[str, float, str, str]] = {
    "bore_mm": ("bore_m", 1e3, "bore", "mm"),
    "rod_mm": ("rod_m", 1e3, "rod", "mm"),
    "mass_kg": ("mass_kg", 1.0, "mass", "kg"),
    "gravity_load_n": ("gravity_load_n", 1.0, "load", "N"),
    "pump_disp_cc_rev": ("pump_disp_m3_rev", 1e6, "pump", "cc/rev"),
    "valve_rated_flow_lpm": ("valve_rated_flow_m3_s", 1 / LPM, "valve", "L/min"),
}
#: Relative difference of a machine parameter beyond which it is another machine (a fleet's
#: machines lie within +-5 % of their type).
MACHINE_TOLERANCE = 0.10
#: Training data beyond this multiple of what the configured machine delivers (pump flow at
#: nominal speed, relief pressure) came from another machine (as ``monitor gap``'s margin).
CAPABILITY_MARGIN = 1.3


@dataclass(frozen=True)
class ModelCard:
    """The header's ``machine``: the loop's name and (None: not named) its machine in the
    units of ``MACHINE_KEYS``, with the simulator YAML it came from."""

    loop: str | None
    machine: dict[str, float] | None = None
    machine_source: str | None = None
    #: The machine commissioned on (the config's ``machine_id``), None: not declared.
    machine_id: str | None = None

    def to_dict(self) -> dict[str, Any]:
        d = {"loop": self.loop, "parameters": self.machine, "source": self.machine_source}
        # Only when declared: a card without it is written as before.
        return d if self.machine_id is None else d | {"id": self.machine_id}

    @classmethod
    def from_dict(cls, d: Any) -> ModelCard:
        if not isinstance(d, dict):
            raise ValueError("header machine must be an object")
        loop, params, source = d.get("loop"), d.get("parameters"), d.get("source")
        if loop is not None and not isinstance(loop, str):
            raise ValueError("header machine.loop must be a loop name or null")
        machine_id = d.get("id")
        if machine_id is not None and not (isinstance(machine_id, str) and machine_id):
            raise ValueError("header machine.id must be a machine id or null")
        if params is not None:
            if (
                not isinstance(params, dict)
                or set(params) != set(MACHINE_KEYS)
                or not all(
                    isinstance(v, (int, float)) and not isinstance(v, bool) for v in params.values()
                )
            ):
                raise ValueError(f"header machine.parameters must hold {', '.join(MACHINE_KEYS)}")
            params = {k: float(params[k]) for k in MACHINE_KEYS}
        return cls(loop, params, None if source is None else str(source)[:200], machine_id)


def machine_values(params: MachineParams) -> dict[str, float]:
    """``params`` in the header's units (mm, kg, N, cc/rev, L/min)."""
    return {k: round(params.value(f) * factor, 6) for k, (f, factor, _, _) in MACHINE_KEYS.items()}


def card_for(
    loop: str | None,
    params: MachineParams | None,
    source: str | None,
    machine_id: str | None = None,
) -> ModelCard:
    """The card ``monitor train`` writes (``machine_id``: the machine commissioned on)."""
    if params is None:
        return ModelCard(loop, machine_id=machine_id)
    return ModelCard(loop, machine_values(params), source, machine_id)


#: The machine the shipped model was commissioned on: the simulated reference machine of
#: config/simulator.yaml, whose recordings the replay logs are.  The shipped config declares
#: it (``machine_id: reference``); a real machine declares its own id.
REFERENCE_MACHINE = "reference"

#: What makes a verdict possible on a machine judged with another machine's model.
COMMISSION = (
    "its hydraulic alarms are withheld, since a healthy machine 5-15 % from the model's machine "
    "looks as faulty to it as a worn one; commission this machine (monitor train on its own "
    "normal operation, with machine_id declared) to judge it"
)


def reference_reason(card: ModelCard | None, machine_id: str | None) -> str | None:
    """Why a model with ``card`` judges another machine than ``machine_id`` (the machine
    the run declares: the config's ``machine_id``, a fleet's machine folder), or None when
    it judges the machine it was commissioned on.

    A model that records no machine (a file from before ``id``, or trained without a
    ``machine_id``) is taken as the judged machine's own, as before.  A run that declares
    no machine is not the model's machine: only a declared id can claim a model's data."""
    commissioned = None if card is None else card.machine_id
    if commissioned is None or commissioned == machine_id:
        return None
    model = (
        "the shipped reference model, commissioned on the reference machine"
        if commissioned == REFERENCE_MACHINE
        else f"a model commissioned on machine {commissioned!r}"
    )
    run = (
        "this machine (the config declares no machine_id)"
        if machine_id is None
        else f"machine {machine_id!r}"
    )
    return f"judged with {model}, not a model of {run}"


def describe(values: dict[str, float]) -> str:
    """``bore 90 mm, rod 50 mm, mass 1500 kg, ...``"""
    return ", ".join(
        f"{label} {values[k]:g} {unit}" for k, (_, _, label, unit) in MACHINE_KEYS.items()
    )


def _capability(params: MachineParams) -> dict[str, tuple[float, str]]:
    """The most each measured signal can read on ``params``' machine (header units)."""
    flow = params.pump.pump_disp_m3_rev * params.pump.nominal_speed_rpm / 60.0 / LPM
    relief = params.line.relief_full_pa / BAR
    return {
        "QP": (flow, "L/min"),
        "PP": (relief, "bar"),
        "PA": (relief, "bar"),
        "PB": (relief, "bar"),
    }


def check_model_for_loop(
    card: ModelCard | None,
    envelope: Envelope | None,
    model_path: object,
    loop: str,
    params: MachineParams | None,
    where: str,
) -> None:
    """Refuse a model (``ModelFileError`` naming the model's loop and machine and the
    config's, ``where`` the config and loop) trained on another loop or machine than the
    loop ``loop`` it is given, whose machine is ``params`` (None: not configured)."""
    if card is None:
        log.info(
            "%s: the model file records no loop or machine (a file from before they were "
            "recorded): loop and machine unknown, not checked against %s",
            model_path,
            where,
        )
    elif card.loop is not None and card.loop != loop:
        raise ModelFileError(
            f"{model_path}: a model of loop {card.loop!r}, given to {where}, "
            f"loop {loop!r}: train one for this loop (monitor train --loop "
            f"{loop})"
        )
    if params is None:
        return
    mine = machine_values(params)
    if card is not None and card.machine is not None:
        off = [
            k
            for k in MACHINE_KEYS
            if abs(card.machine[k] - mine[k]) > MACHINE_TOLERANCE * max(abs(mine[k]), 1e-9)
        ]
        if off:
            raise ModelFileError(
                f"{model_path}: trained on a machine with {describe(card.machine)}"
                f"; {where} has {describe(mine)} ({', '.join(off)} differ)"
            )
    if envelope is not None and envelope.source == "training":
        seen = {s: envelope.range_of(s)[1] for s in envelope.signals}
        check_seen(seen, params, f"{model_path}: trained on", where)


def check_seen(seen: dict[str, float], params: MachineParams, what: str, where: str) -> None:
    """Refuse data (``seen``: the largest value per signal) that the machine ``params`` of
    ``where`` cannot produce: more than ``CAPABILITY_MARGIN`` times its pump's flow at
    nominal speed or its relief pressure.  ``what`` starts the message."""
    for signal, (most, unit) in _capability(params).items():
        if seen.get(signal, 0.0) > CAPABILITY_MARGIN * most:
            raise ModelFileError(
                f"{what} {signal} up to {seen[signal]:.4g} {unit}, more than "
                f"{CAPABILITY_MARGIN:g} x the {most:.4g} {unit} of {where}'s "
                f"machine ({describe(machine_values(params))}): another "
                "machine"
            )
