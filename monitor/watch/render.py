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
    """The screen, top to bottom: each loop's alarm, the monitor's status and DM1, the
    sensors' latest values and the frames seen; every line cut at ``width``."""
    out = [
        f"monitor watch  {source}  frames {state.total}  (q: quit)",
        "",
        *_alarms(state, now_mono, max(10, min(40, width - 60))),
        "",
        *_status(state, now_mono),
        *_dm1(state),
        "",
        "  ".join(
            f"{k} {state.values[k]:7.2f} {_UNITS[k]}" if k in state.values else f"{k} -"
            for k in SENSORS
        ),
        *_frames(state, width),
    ]
    return [x[:width] for x in out]


def _alarms(state: WatchState, now_mono: float, bar: int) -> list[str]:
    """One line per loop from its MON_Alarm frames, J / eps0 as a bar of ``bar`` cells."""
    out = [f"{'loop':<18}{'state':<14}{'J / eps0':<{bar + 9}}{'fault':<14}alarms"]
    if not state.alarms:
        out.append("  no MON_Alarm frame yet (is the monitor running on this bus?)")
    for name, a in sorted(state.alarms.items()):
        age = now_mono - a.seen_mono
        stale = f"  ({age:.0f} s ago)" if age > 3.0 else ""
        out.append(
            f"{name:<18}{a.state.upper():<14}{j_bar(a.ratio, bar):<{bar + 9}}"
            f"{a.fault:<14}{a.alarms}{stale}"
        )
    return out


def _status(state: WatchState, now_mono: float) -> list[str]:
    s = state.status
    if not s:
        return ["MON_Status: none yet"]
    age = now_mono - state.status_mono
    return [
        f"MON_Status ({age:.0f} s ago): state {s.get('State')}, operating {s.get('OpState')}, "
        f"range {s.get('OutOfRange')}, sensor check {s.get('SensorCheck')}",
        f"  frames received {s.get('RxFrames')}, rejected {s.get('RejectedFrames')}, "
        f"dropped {s.get('DroppedFrames')}; bus events {s.get('BusEvents')}",
    ]


def _dm1(state: WatchState) -> list[str]:
    """Each source address's lamps and active DTCs, named where they are the monitor's."""
    if not state.dm1:
        return ["DM1: none seen"]
    out = []
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
    return out


def _frames(state: WatchState, width: int) -> list[str]:
    """Frames decoded (and rejected) by name, wrapped at ``width``."""
    names = sorted(set(state.frames) | set(state.rejected))
    if not names:
        return ["frames seen here: none decoded yet"]
    out = []
    line = "frames seen here:"
    for n in names:
        item = f" {n} {state.frames.get(n, 0)}" + (
            f" ({state.rejected[n]} rejected)" if state.rejected.get(n) else ""
        )
        if len(line) + len(item) > width:
            out.append(line)
            line = " " * 17
        line += item
    out.append(line)
    return out
