"""``monitor detect --config`` decodes a log with the config's ``dbc`` also without
``--loop`` (issue 20: it used the shipped DBC and rejected every frame of a machine whose
pressures come on another ID)."""

from __future__ import annotations

import json

from monitor.cli import main
from monitor.resources import resource_path

OLD, NEW = "0CFF1021", "0CFF1821"  # HYD_Pressures moved to another (unused) ID


def test_detect_uses_the_config_dbc_without_loop(tmp_path, capsys) -> None:
    dbc = resource_path("dbc", "monitor.dbc").read_text()
    assert str(0x8CFF1021) in dbc and str(0x8CFF1821) not in dbc  # DBC IDs carry bit 31
    (tmp_path / "moved.dbc").write_text(dbc.replace(str(0x8CFF1021), str(0x8CFF1821)))
    log = resource_path("replay", "spool_wear.log").read_text()
    (tmp_path / "moved.log").write_text(log.replace(f" {OLD}#", f" {NEW}#"))
    model = resource_path("config", "boom_default.model.npz")
    (tmp_path / "monitor.yaml").write_text(
        f"dbc: moved.dbc\nmodel: {model}\nmachine_id: reference\n"
    )

    def verdict(args: list[str]) -> tuple[int, str]:
        out = tmp_path / "s.json"
        code = main(["detect", *args, "--summary", str(out)])
        capsys.readouterr()
        return code, json.loads(out.read_text())["verdict"]

    reference = verdict([str(resource_path("replay", "spool_wear.log"))])
    assert reference[1] == "fault"  # the shipped recording of a worn spool
    moved = verdict([str(tmp_path / "moved.log"), "--config", str(tmp_path / "monitor.yaml")])
    assert moved == reference
