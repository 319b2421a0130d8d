"""The `monitor watch` screen as plain lines (curses only draws them), so it can be tested."""

from __future__ import annotations

from monitor.codec.j1939.dtc import DEFAULT_FAULT_SPN, DEFAULT_SENSOR_SPN
from monitor.watch.state import SENSORS, WatchState

_UNITS = {"PP": "bar", "PA": "bar", "PB": "bar", "QP": "L/min"}
_NAMES = {spn: f"fault {name}" for name, spn in DEFAULT_FAULT_SPN.items()} | {
    spn: f"sensor {name}" for name, spn in DEFAULT_SENSOR_SPN.items()
}


def j_bar(ratio: float | None, width: int) -> str:
    """J / eps0 as a bar of ``width`` cells: the threshold (1.0) at 3/4 of the width, ``|``."""
    if ratio is None:
        return "[" + " " * width + "]  n/a"
    at = int(width * 0.75)  # eps0
    fill = max(0, min(width, round(ratio * at)))
    cells = ["#" if k < fill else " " for k in range(width)]
    cells[at] = "|"
    return "[" + "".join(cells) + f"] {ratio:5.2f}"


def render(state: WatchState, source: str, now_mono: float, width: int = 100) -> list[str]:
    bar = max(10, min(40, width - 60))
    out = [f"monitor watch  {source}  frames {state.total}  (q: quit)", ""]
    out.append(f"{'loop':<18}{'state':<14}{'J / eps0':<{bar + 9}}{'fault':<14}alarms")
    if not state.alarms:
        out.append("  no MON_Alarm frame yet (is the monitor running on this bus?)")
    for name, a in sorted(state.alarms.items()):
        age = now_mono - a.seen_mono
        stale = f"  ({age:.0f} s ago)" if age > 3.0 else ""
        out.append(
            f"{name:<18}{a.state.upper():<14}{j_bar(a.ratio, bar):<{bar + 9}}"
            f"{a.fault:<14}{a.alarms}{stale}"
        )
    out.append("")
    s = state.status
    if s:
        age = now_mono - state.status_mono
        out.append(
            f"MON_Status ({age:.0f} s ago): state {s.get('State')}, operating {s.get('OpState')}, "
            f"range {s.get('OutOfRange')}, sensor check {s.get('SensorCheck')}"
        )
        out.append(
            f"  frames received {s.get('RxFrames')}, rejected {s.get('RejectedFrames')}, "
            f"dropped {s.get('DroppedFrames')}; bus events {s.get('BusEvents')}"
        )
    else:
        out.append("MON_Status: none yet")
    if not state.dm1:
        out.append("DM1: none seen")
    for sa, (lamps, dtcs) in sorted(state.dm1.items()):
        lit = ", ".join(lamps) if lamps else "no lamp"
        if not dtcs:
            out.append(f"DM1 from 0x{sa:02X}: {lit}; no active DTC")
        for d in dtcs:
            what = _NAMES.get(d.spn, "")
            out.append(
                f"DM1 from 0x{sa:02X}: {lit}; SPN {d.spn} FMI {d.fmi} OC {d.oc}"
                + (f" ({what})" if what else "")
            )
    out.append("")
    out.append(
        "  ".join(
            f"{k} {state.values[k]:7.2f} {_UNITS[k]}" if k in state.values else f"{k} -"
            for k in SENSORS
        )
    )
    names = sorted(set(state.frames) | set(state.rejected))
    if not names:
        out.append("frames seen here: none decoded yet")
    line = "frames seen here:"
    for n in names:
        item = f" {n} {state.frames.get(n, 0)}" + (
            f" ({state.rejected[n]} rejected)" if state.rejected.get(n) else ""
        )
        if len(line) + len(item) > width:
            out.append(line)
            line = " " * 17
        line += item
    if names:
        out.append(line)
    return [x[:width] for x in out]
