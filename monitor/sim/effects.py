"""Effects the nominal model leaves out, enabled with physical parameters (their catalogue:
``monitor.sim.catalogue``).

Every effect is off in the nominal model.  An ``Effect`` is a name plus its parameter values
in the units their names carry; the kernel converts them to SI.  The sim-to-real tool fits
these parameters, so they are always passed in, never read from globals.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from monitor.errors import ConfigError
from monitor.sim.catalogue import (
    CATALOGUE,
    SENSOR_CAL_SIGNALS,
    ChoiceSpec,
    EffectSpec,
    ParamSpec,
    SensorCalSignal,
)

__all__ = [
    "CATALOGUE",
    "SENSOR_CAL_SIGNALS",
    "ChoiceSpec",
    "Effect",
    "EffectSpec",
    "ParamSpec",
    "SensorCalSignal",
    "describe_catalogue",
    "parse_effect",
]


@dataclass(frozen=True)
class Effect:
    """One enabled effect with every parameter set (defaults filled in); ``labels`` holds
    the named choices (``sensor_calibration``'s signal)."""

    name: str
    params: dict[str, float] = field(default_factory=dict)
    labels: dict[str, str] = field(default_factory=dict)

    @classmethod
    def make(cls, name: str, **values: float | str) -> Effect:
        spec = CATALOGUE.get(name)
        if spec is None:
            raise ConfigError(f"unknown effect {name!r}; known: {', '.join(CATALOGUE)}")
        params = {p.name: p.default for p in spec.params}
        labels = {c.name: c.default for c in spec.choices}
        for key, value in values.items():
            choice = next((c for c in spec.choices if c.name == key), None)
            if choice is not None:
                if value not in choice.options:
                    raise ConfigError(
                        f"effect {name}: {key} = {value!r} is not one of "
                        f"{', '.join(choice.options)}"
                    )
                labels[key] = str(value)
                continue
            p = spec.param(key)
            value = float(value)
            if not p.low <= value <= p.high:
                raise ConfigError(
                    f"effect {name}: {key} = {value:g} {p.unit} is outside {p.low:g}..{p.high:g}"
                )
            params[key] = value
        if name == "sensor_calibration" and "offset" in values and "gain" not in values:
            params["gain"] = 1.0  # an offset alone is an offset, not an offset and a gain
        _check_relations(name, params, labels)
        return cls(name, params, labels)


def _check_relations(name: str, params: dict[str, float], labels: dict[str, str]) -> None:
    if name == "sensor_calibration":
        sig = SENSOR_CAL_SIGNALS[labels["signal"]]
        if abs(params["offset"]) > sig.max_offset:
            raise ConfigError(
                f"effect sensor_calibration: offset = {params['offset']:g} {sig.unit} is outside "
                f"-{sig.max_offset:g}..{sig.max_offset:g} for {labels['signal']}"
            )
    if name == "cylinder_friction" and params["static_n"] < params["coulomb_n"]:
        raise ConfigError(
            f"effect cylinder_friction: static_n = {params['static_n']:g} N must be at least "
            f"coulomb_n = {params['coulomb_n']:g} N"
        )
    if name == "oil_viscosity" and params["nu100_cst"] >= params["nu40_cst"]:
        raise ConfigError("effect oil_viscosity: nu100_cst must be below nu40_cst")


def parse_effect(text: str) -> Effect:
    """Parse the CLI form ``NAME[:param=value,...]``."""
    name, _, rest = text.partition(":")
    values: dict[str, float | str] = {}
    spec = CATALOGUE.get(name.strip())
    choices = {c.name for c in spec.choices} if spec is not None else set()
    if rest:
        for item in rest.split(","):
            key, eq, raw = item.partition("=")
            if not eq:
                raise ConfigError(f"--effect {text!r}: expected param=value, got {item!r}")
            if key.strip() in choices:
                values[key.strip()] = raw.strip()
                continue
            try:
                values[key.strip()] = float(raw)
            except ValueError:
                raise ConfigError(
                    f"--effect {text!r}: {key.strip()} = {raw!r} is not a number"
                ) from None
    return Effect.make(name.strip(), **values)


def describe_catalogue() -> str:
    """Text for --help: every effect, its parameters with units, defaults and ranges."""
    lines = []
    for spec in CATALOGUE.values():
        lines.append(f"  {spec.name}: {spec.doc}")
        for c in spec.choices:
            lines.append(
                f"      {c.name} [name] default {c.default}, one of {'|'.join(c.options)}: {c.doc}"
            )
        for p in spec.params:
            rng = f"default {p.default:g}, range {p.low:g}..{p.high:g}"
            lines.append(f"      {p.name} [{p.unit}] {rng}: {p.doc}")
    return "\n".join(lines)
