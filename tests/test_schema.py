"""One schema engine for both YAML files: a strict reader (no aliases, no duplicate keys, a
size cap) and typed sections from dataclass field metadata (finite numbers only)."""

from __future__ import annotations

from pathlib import Path

import pytest

from monitor.config.settings import load_config
from monitor.errors import ConfigError
from monitor.sim.machine import load_machine

BOMB = """a: &a ["x", "x", "x", "x", "x", "x", "x", "x", "x"]
b: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a]
c: &c [*b, *b, *b, *b, *b, *b, *b, *b, *b]
d: &d [*c, *c, *c, *c, *c, *c, *c, *c, *c]
e: &e [*d, *d, *d, *d, *d, *d, *d, *d, *d]
f: &f [*e, *e, *e, *e, *e, *e, *e, *e, *e]
g: [*f, *f, *f, *f, *f, *f, *f, *f, *f]
"""


@pytest.mark.parametrize("loader", [load_config, load_machine], ids=["monitor", "simulator"])
def test_a_yaml_bomb_is_refused_at_its_first_alias(tmp_path: Path, loader) -> None:
    path = tmp_path / "bomb.yaml"
    path.write_text(BOMB)  # 9^7 = 4.8 million strings if expanded
    with pytest.raises(ConfigError, match=r"bomb.yaml: line 2: YAML aliases"):
        loader(path)


@pytest.mark.parametrize(
    ("text", "loader", "message"),
    [
        (
            "bus:\n  channel: can0\n  channel: can1\n",
            load_config,
            "line 3: key 'channel' is given twice",
        ),
        (
            "alarm:\n  min_engine_rpm: .nan\n",
            load_config,
            "alarm.min_engine_rpm must be a finite number",
        ),
        ("storage:\n  quota_mb: .inf\n", load_config, "storage.quota_mb must be a finite number"),
        ("detector:\n  horizon: 0\n", load_config, "detector.horizon must be >= 1"),
        ("load:\n  mass_kg: 400\n  mass_kg: 500\n", load_machine, "key 'mass_kg' is given twice"),
        ("load:\n  mass_kg: .inf\n", load_machine, "load.mass_kg must be a finite number"),
        ("bus: [1, 2\n", load_config, "line 2"),
    ],
    ids=["duplicate", "nan", "inf", "horizon", "sim-duplicate", "sim-inf", "broken"],
)
def test_bad_values_are_one_line_naming_file_key_and_value(tmp_path, text, loader, message):
    path = tmp_path / "c.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as err:
        loader(path)
    assert str(err.value).startswith(f"{path}:") and message in str(err.value)
    assert len(str(err.value)) < 300 and "\n" not in str(err.value)


def test_an_oversized_file_is_refused_before_it_is_parsed(tmp_path: Path) -> None:
    path = tmp_path / "big.yaml"
    path.write_text("# " + "x" * 2_000_000 + "\n")
    with pytest.raises(ConfigError, match="too large for a config"):
        load_config(path)


def test_every_setting_declares_itself_once_with_its_check() -> None:
    """The reference docs read the checks and units from the same field metadata."""
    from dataclasses import fields

    from monitor.bus.reader import BusConfig

    meta = {f.name: f.metadata for f in fields(BusConfig)}
    assert meta["bitrate"]["unit"] == "bit/s" and not meta["bitrate"]["check"](5)
    assert meta["queue_frames"]["check"](100) and not meta["queue_frames"]["check"](99)


def test_deeply_nested_yaml_is_one_clear_error_not_a_recursion_crash(tmp_path) -> None:
    from monitor.sim.machine import load_machine

    p = tmp_path / "deep.yaml"
    p.write_text("bus: " + "[" * 5000 + "]" * 5000 + "\n")
    for loader in (load_config, load_machine):
        with pytest.raises(ConfigError, match=r"deep\.yaml: line 1: nested deeper than 32 levels"):
            loader(p)


def test_a_section_made_of_records_keeps_its_yaml_keys_flat(tmp_path: Path) -> None:
    """``plausibility`` holds one record per check; users still write its keys flat, each
    lands in its record, the rest keep their defaults, and a wrong key names the flat keys."""
    path = tmp_path / "monitor.yaml"
    path.write_text("plausibility:\n  frozen_s: 0.5\n  rest_max_bar: 3\n  range_s: 0.2\n")
    plaus = load_config(path).gating.plausibility
    assert plaus.frozen.frozen_s == 0.5
    assert plaus.rest.rest_max_bar == 3.0 and plaus.rest.rest_settle_s == 30.0
    assert plaus.signal_range.range_s == 0.2 and plaus.signal_range.pressure_max_bar == 400.0
    assert plaus.stuck.stuck_s == 20.0  # not written: the shipped default
    path.write_text("plausibility:\n  rest: {rest_max_bar: 3}\n")
    with pytest.raises(ConfigError, match=r"unknown key plausibility\.rest; known: pressure_min"):
        load_config(path)
    path.write_text("plausibility:\n  rest_max_bar: -1\n")
    with pytest.raises(ConfigError, match=r"monitor\.yaml: plausibility\.rest_max_bar must be"):
        load_config(path)
