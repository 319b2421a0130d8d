"""The fleet web page, episodes and their names, acknowledgements and SQL queries, from a
logs.parquet written by hand (the browser test is tests/test_fleet_browser.py)."""

from __future__ import annotations

import json
import re
import threading
import urllib.parse
import urllib.request
from types import SimpleNamespace

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from monitor.cli import main
from monitor.codec.j1939 import dtc
from monitor.errors import ConfigError
from monitor.fleet.acks import read_acks, record
from monitor.fleet.actions import FAULT_ACTIONS, SENSOR_ACTIONS, markdown_table
from monitor.fleet.episodes import log_episodes, machine_fault
from monitor.fleet.store import LOG_SCHEMA

J1939 = SimpleNamespace(
    fault_spn=dtc.DEFAULT_FAULT_SPN,
    fault_fmi=dtc.DEFAULT_FAULT_FMI,
    sensor_spn=dtc.DEFAULT_SENSOR_SPN,
    sensor_fmi=dtc.DEFAULT_SENSOR_FMI,
    check_fmi=dtc.DEFAULT_CHECK_FMI,
)
# By hand from J1939-71's proprietary range (first SPN 520192) and our numbering:
PISTON = (520192, 7)  # piston_wear: the first fault SPN, FMI 7 (mechanical, out of adjustment)
SPOOL = (520194, 7)  # spool_wear: the third
QP_FROZEN = (520192 + 16 + 7, 10)  # QP: the 8th sensor SPN from 520208; frozen: FMI 10


def _ep(kind, start, end, name, votes=None, check=None, spn_fmi=PISTON):
    return {
        "kind": kind,
        "start_t": start,
        "end_t": end,
        "duration_s": end - start,
        "open": False,
        "name": name,
        "check": check,
        "votes": votes or {},
        "spn": spn_fmi[0],
        "fmi": spn_fmi[1],
    }


def _row(machine, day, verdict="healthy", level=0.3, episodes=(), **kw):
    r = {name: None for name in LOG_SCHEMA.names}
    r |= {
        "machine": machine,
        "log": f"{machine}/logs/day{day:02d}.log",
        "sha256": f"{day}",
        "verdict": verdict,
        "alarm": verdict == "fault",
        "sensor_fault": verdict == "sensor_fault",
        "max_j_ratio": level,
        "p50_j_ratio": level / 3,
        "model": "commissioned",
        "judged_s": 60.0,
        "episodes": json.dumps(list(episodes)),
    }
    return r | kw


def _results(tmp_path):
    """M01: piston seal from day 3, its episodes named differently one by one; M02 healthy;
    M03: QP frozen from day 2."""
    rows = [_row("M01", 1), _row("M01", 2)]
    rows.append(
        _row(
            "M01",
            3,
            "fault",
            2.5,
            [
                _ep(
                    "fault",
                    10.0,
                    20.0,
                    "spool_wear",
                    {"spool_wear": 30, "piston_wear": 10},
                    spn_fmi=SPOOL,
                )
            ],
        )
    )
    rows.append(
        _row(
            "M01",
            4,
            "fault",
            3.1,
            [
                _ep("fault", 5.0, 40.0, "piston_wear", {"piston_wear": 50, "unknown": 9}),
                _ep(
                    "fault",
                    50.0,
                    55.0,
                    "spool_wear",
                    {"spool_wear": 5, "piston_wear": 3},
                    spn_fmi=SPOOL,
                ),
            ],
        )
    )
    rows += [_row("M02", d) for d in (1, 2, 3, 4)]
    rows += [_row("M03", 1)] + [
        _row(
            "M03",
            d,
            "sensor_fault",
            0.2,
            [_ep("sensor_fault", 31.0, 60.0, "QP", check="frozen", spn_fmi=QP_FROZEN)],
        )
        for d in (2, 3, 4)
    ]
    pq.write_table(pa.Table.from_pylist(rows, LOG_SCHEMA), tmp_path / "logs.parquet")
    return tmp_path


def test_a_log_episode_carries_the_dm1_code_the_daemon_sends():
    named = [
        {
            "start_t": 3.0,
            "end_t": None,
            "votes": {"unknown": 4, "piston_wear": 2},
            "fault": "piston_wear",
        }
    ]
    events = [
        {"t": 0.0, "state": "normal"},
        {"t": 1.0, "state": "sensor_fault", "sensor": None, "sensor_check": None},
        {"t": 1.5, "state": "sensor_fault", "sensor": "QP", "sensor_check": "frozen"},
        {"t": 2.0, "state": "normal"},
        {"t": 3.0, "state": "fault"},
    ]
    eps = json.loads(log_episodes(named, events, 9.0, J1939))
    sensor, fault = eps
    assert (sensor["kind"], sensor["name"], sensor["check"]) == ("sensor_fault", "QP", "frozen")
    assert (sensor["spn"], sensor["fmi"], sensor["duration_s"]) == (*QP_FROZEN, 1.0)
    assert (fault["name"], fault["spn"], fault["fmi"]) == ("piston_wear", *PISTON)
    # Open at the end of the log: it ends there, and says so.
    assert (fault["end_t"], fault["open"], fault["duration_s"]) == (9.0, True, 6.0)


def test_a_stale_signal_keeps_its_spn_with_the_stale_fmi_and_an_unnamed_one_is_unknown():
    events = [
        {"t": 1.0, "state": "sensor_fault", "sensor": "PA", "sensor_check": "stale"},
        {"t": 4.0, "state": "normal"},
        {"t": 5.0, "state": "sensor_fault"},
    ]
    pa_, unknown = json.loads(log_episodes([], events, 6.0, J1939))
    assert (pa_["spn"], pa_["fmi"]) == (520192 + 16 + 5, 9)  # PA: 6th sensor; FMI 9 rate
    assert (unknown["name"], unknown["spn"], unknown["fmi"]) == ("unknown", 520192 + 31, 9)


def test_the_machine_is_named_from_every_episodes_votes_not_from_the_last_episode():
    # Votes by hand: piston_wear 10 + 50 + 3 = 63, spool_wear 30 + 5 = 35, unknown 9 (a
    # known name beats unknown whatever its count).  Two of three episodes were named
    # spool_wear on their own evidence; the machine is piston_wear, 63 / 107 = 59 %.
    per = _rows_by_machine(_results_rows())
    f = machine_fault(per["M01"])
    assert f.name == "piston_wear" and f.votes == {
        "spool_wear": 35,
        "piston_wear": 63,
        "unknown": 9,
    }
    assert (f.episodes, f.renamed) == (3, 2)
    assert f.evidence == "isolation 59 % of 107 fault samples over 3 episodes, 2 named otherwise"


def _results_rows():
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as tmp:
        return pq.read_table(_results(Path(tmp)) / "logs.parquet").to_pylist()


def _rows_by_machine(rows):
    out: dict[str, list] = {}
    for r in rows:
        out.setdefault(r["machine"], []).append(r)
    return out


def test_every_fault_and_sensor_check_has_an_action_text():
    assert set(FAULT_ACTIONS) == set(dtc.DEFAULT_FAULT_SPN)
    assert set(SENSOR_ACTIONS) == set(dtc.DEFAULT_CHECK_FMI) | {"stale", "unknown"}
    table = markdown_table()
    assert "| fault | `piston_wear` | piston seal suspected | inspect the boom cylinder" in table


def test_the_html_page_names_state_fault_since_and_action_and_loads_nothing_remote(tmp_path):
    res = _results(tmp_path)
    out = tmp_path / "html"
    assert main(["fleet", "report", str(res), "--html", str(out)]) == 0
    index = (out / "index.html").read_text()
    m01 = _table_row(index, "M01")
    assert "FAULT" in m01 and "piston_wear: piston seal suspected" in m01
    assert "inspect the boom cylinder for internal leakage" in m01
    assert "<td>day03</td>" in m01  # first seen
    m03 = _table_row(index, "M03")
    assert "SENSOR FAULT" in m03 and "QP frozen" in m03 and "<td>day02</td>" in m03
    assert "check the sensor and its wiring" in m03
    assert "QP: pump outlet flow (L/min)" in m03  # what the signal is, for a newcomer
    assert "healthy" in _table_row(index, "M02") and "nothing to do" in _table_row(index, "M02")
    # Episodes per code and day (days 02, 03, 04): each episode under the code of its own
    # name, as DM1 sent it: piston_wear once on day 4, spool_wear on days 3 and 4, QP every
    # day from day 2.
    codes = index[index.index('id="codes"') :]
    for (spn, _fmi), want in (
        (PISTON, ["", "", "1"]),
        (SPOOL, ["", "1", "1"]),
        (QP_FROZEN, ["1", "1", "1"]),
    ):
        line = codes[codes.index(f'<td class="num">{spn}</td>') :].split("</tr>")[0]
        assert re.findall(r'<td class="num">(\d*)</td>', line)[2:] == want
    # Offline: every script is a file beside the page, none from a network.
    for page in out.glob("*.html"):
        for src in re.findall(r'<script[^>]*src="([^"]+)"', page.read_text()):
            assert src == "plotly.min.js" and (out / src).stat().st_size > 1_000_000
    machine = (out / "machine-M01.html").read_text()
    assert "isolation votes" in machine and "spool_wear 75 %, piston_wear 25 %" in machine
    assert "--fleet FLEET" in machine  # no fleet folder given: says how to get the signals
    # An episode named otherwise says so, and what to do follows the machine's name.
    alarms = (out / "alarms.html").read_text()
    odd = alarms[alarms.index('data-alarm="M01/logs/day04.log#fault@50.00"') :].split("</tr>")[0]
    assert "worn valve spool suspected (this episode); the machine: piston seal suspected" in odd
    assert "inspect the boom cylinder" in odd
    assert "monitor fleet serve RESULTS" in (out / "alarms.html").read_text()


def _table_row(html: str, machine: str) -> str:
    start = html.index(f'<tr id="row-{machine}">')
    return html[start : html.index("</tr>", start)]


def test_the_markdown_report_still_works_beside_the_html_one(tmp_path):
    res = _results(tmp_path)
    assert (
        main(
            [
                "fleet",
                "report",
                str(res),
                "--out",
                str(tmp_path / "md"),
                "--html",
                str(tmp_path / "html"),
            ]
        )
        == 0
    )
    assert "| M01 | 4 | fault |" in (tmp_path / "md" / "fleet.md").read_text()
    assert (tmp_path / "html" / "index.html").is_file()


def test_report_without_a_page_to_write_is_one_line(tmp_path, capsys):
    _results(tmp_path)
    assert main(["fleet", "report", str(tmp_path)]) == 2
    assert "give --out DIR" in capsys.readouterr().err


def test_acknowledgements_append_and_the_newest_line_is_the_status(tmp_path):
    import datetime as dt

    t0 = dt.datetime(2026, 1, 5, 8, 0, tzinfo=dt.timezone.utc)
    record(tmp_path, "M01/logs/day03.log#fault@10.00", "acknowledge", "Ana", now=t0)
    record(
        tmp_path,
        "M01/logs/day03.log#fault@10.00",
        "shelve",
        "Ben",
        "parts ordered",
        shelve_days=2,
        now=t0 + dt.timedelta(hours=1),
    )
    lines = (tmp_path / "alarm-acks.jsonl").read_text().splitlines()
    assert len(lines) == 2  # appended, never rewritten
    s = read_acks(tmp_path)["M01/logs/day03.log#fault@10.00"]
    assert (s.action, s.by, s.until) == ("shelve", "Ben", "2026-01-07T09:00:00+00:00")
    assert s.shelved(t0 + dt.timedelta(days=1)) and not s.shelved(t0 + dt.timedelta(days=3))
    with pytest.raises(ConfigError, match="a name is required"):
        record(tmp_path, "x", "acknowledge", "  ")
    assert not (tmp_path / "logs.parquet").exists()  # nothing written to the tables


def test_serve_acknowledges_through_the_form_and_keeps_it_beside_the_results(tmp_path):
    from http.server import ThreadingHTTPServer

    from monitor.fleet.report import load_rows
    from monitor.fleet.serve import _handler
    from monitor.fleet.web import Site

    res = _results(tmp_path)
    before = (res / "logs.parquet").read_bytes()
    site = Site(res, load_rows(res))
    site.write(tmp_path / "pages")
    server = ThreadingHTTPServer(
        ("127.0.0.1", 0), _handler(site, tmp_path / "pages", threading.Lock())
    )
    threading.Thread(target=server.serve_forever, daemon=True).start()
    base = f"http://127.0.0.1:{server.server_address[1]}"
    try:
        page = urllib.request.urlopen(f"{base}/alarms.html").read().decode()
        alarm = re.findall(r'data-alarm="([^"]+)"', page)[0]
        assert 'name="by"' in page  # live: the form is there
        form = urllib.parse.urlencode(
            {"alarm": alarm, "action": "acknowledge", "by": "Ana", "note": "seal kit ordered"}
        ).encode()
        after = urllib.request.urlopen(f"{base}/ack", data=form).read().decode()  # 303 followed
        row = after[after.index(f'data-alarm="{alarm}"') :].split("</tr>")[0]
        assert "acknowledged by Ana at" in row and "seal kit ordered" in row
        bad = urllib.parse.urlencode({"alarm": alarm, "action": "acknowledge"}).encode()
        with pytest.raises(urllib.error.HTTPError) as e:
            urllib.request.urlopen(f"{base}/ack", data=bad)
        assert e.value.code == 400
    finally:
        server.shutdown()
        server.server_close()
    assert read_acks(res)[alarm].by == "Ana"
    assert (res / "logs.parquet").read_bytes() == before


def test_query_answers_which_machines_had_qp_faults(tmp_path, capsys):
    res = _results(tmp_path)
    sql = (
        "SELECT machine, count(*) AS episodes, min(log) AS first FROM episodes "
        "WHERE name = 'QP' GROUP BY machine"
    )
    assert main(["fleet", "query", str(res), sql]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].split() == ["machine", "episodes", "first"]
    assert out[2].split() == ["M03", "3", "M03/logs/day02.log"] and out[-1] == "(1 row)"
    assert (
        main(
            [
                "fleet",
                "query",
                str(res),
                "SELECT verdict, count(*) n FROM logs GROUP BY verdict ORDER BY verdict",
                "--csv",
            ]
        )
        == 0
    )
    assert capsys.readouterr().out.splitlines() == [
        "verdict,n",
        "fault,2",
        "healthy,7",
        "sensor_fault,3",
    ]


def test_a_bad_query_is_one_line_and_a_non_zero_exit(tmp_path, capsys):
    res = _results(tmp_path)
    assert main(["fleet", "query", str(res), "SELECT nope FROM logs"]) != 0
    err = capsys.readouterr().err
    assert "query:" in err and "nope" in err and "Traceback" not in err


def test_a_judged_log_names_its_episode_from_every_fault_sample_of_it():
    # The shipped piston-wear demo log with the shipped model: one episode from the alarm
    # to the end of the log.  Its votes are its fault samples, counted apart from the
    # detector's state per sample; the name and DM1 code are piston_wear's (by hand above).
    import numpy as np
    from naive_frames import recording_from_candump

    from monitor.detection.alarm import State
    from monitor.detection.offline import detect
    from monitor.fleet.pipeline import judge_log
    from monitor.model.modelfile import load_model
    from monitor.resources import resource_path

    model_path, log = (
        resource_path("config", "boom_default.model.npz"),
        resource_path("replay", "piston_wear.log"),
    )
    # The shipped log of the reference machine, judged as that machine.
    judged = judge_log(model_path.read_bytes(), str(log), None, "reference")
    (ep,) = json.loads(judged.row["episodes"])
    raised = [e for e in judged.events if e["state"] == "fault"]
    assert ep["start_t"] == raised[0]["t"] and ep["open"] is True
    det = detect(load_model(model_path), recording_from_candump(log))
    t = det.t - det.t[0]
    in_fault = int(np.sum((det.state == State.FAULT) & (t >= ep["start_t"])))
    assert sum(ep["votes"].values()) == in_fault > 0
    assert (ep["name"], ep["spn"], ep["fmi"]) == ("piston_wear", *PISTON)
    assert ep["end_t"] == pytest.approx(t[-1]) and judged.row["fault"] == ep["name"]


def test_an_episode_of_hours_is_plotted_thinned_and_a_short_one_sample_by_sample():
    import numpy as np

    from monitor.fleet.webplots import AROUND_S, MAX_POINTS, _window

    t = np.arange(0, 8 * 3600, 0.01)  # an 8-hour log at 100 Hz
    long = t[_window(t, 600.0, 600.0 + 3 * 3600)]  # a 3-hour episode
    assert len(long) <= MAX_POINTS and long[0] == pytest.approx(600.0 - AROUND_S)
    assert long[-1] == pytest.approx(600.0 + 3 * 3600 + AROUND_S, abs=(long[1] - long[0]))
    short = t[_window(t, 100.0, 110.0)]  # 10 s and 20 s either side: every sample
    assert len(short) == 5000 and np.all(np.diff(short) == pytest.approx(0.01))


def test_results_from_before_episodes_say_their_alarms_are_missing(tmp_path):
    rows = [_row("M01", 1), _row("M01", 2, "fault", 2.0, fault="piston_wear")]
    rows[1]["episodes"] = None  # written before the column
    pq.write_table(pa.Table.from_pylist(rows, LOG_SCHEMA), tmp_path / "logs.parquet")
    assert main(["fleet", "report", str(tmp_path), "--html", str(tmp_path / "h")]) == 0
    index = (tmp_path / "h" / "index.html").read_text()
    assert "1 logs with an alarm or sensor fault were judged\nbefore" in index
    # The machine is still named from the row's own fault.
    assert "piston_wear: piston seal suspected" in _table_row(index, "M01")


def test_a_sensor_finding_reads_as_signal_and_what_is_wrong():
    from monitor.fleet.actions import sensor_label

    assert sensor_label("QP", "frozen") == "QP frozen"
    assert sensor_label("PA", "stale") == "PA silent (no frames)"
    assert sensor_label("unknown", None) == "a sensor (not named) faulty"
    assert sensor_label("PB", "a_check_added_later") == "PB faulty"


def test_a_sensor_finding_says_what_its_signal_measures():
    # The contract's words for the signals (docs/reference/contracts.md): QP is the pump
    # outlet flow in L/min, PA the cap-side port pressure in bar.
    from monitor.fleet.actions import signal_meaning

    assert signal_meaning("QP") == "QP: pump outlet flow (L/min)"
    assert signal_meaning("Stick_PA") == "Stick_PA: valve port A (cap side) pressure, gauge (bar)"
    assert signal_meaning("unknown") == ""


def test_a_machine_in_fault_is_named_by_its_fault_though_a_sensor_episode_came_later():
    from monitor.fleet.fleetview import machine_view

    rows = [
        _row(
            "M05",
            1,
            "fault",
            2.0,
            [
                _ep("fault", 5.0, 30.0, "piston_wear", {"piston_wear": 40}),
                _ep("sensor_fault", 40.0, 50.0, "QP", check="frozen", spn_fmi=QP_FROZEN),
            ],
        )
    ]
    v = machine_view("M05", rows)
    assert (v.state, v.finding) == ("fault", "piston_wear: piston seal suspected")
    assert v.what_to_do.startswith("inspect the boom cylinder")
    v = machine_view(
        "M05",
        [
            *rows,
            _row(
                "M05",
                2,
                "sensor_fault",
                0.3,
                [_ep("sensor_fault", 1.0, 9.0, "QP", check="frozen", spn_fmi=QP_FROZEN)],
            ),
        ],
    )
    assert (v.state, v.finding, v.since) == ("sensor_fault", "QP frozen", "day01")


def test_a_fault_code_means_what_its_episodes_were_sent_as_not_the_machine_name():
    # M06 is named piston_wear (40 of 50 votes) but its second episode was sent as spool
    # wear: the spool code's meaning stays "worn valve spool suspected", with M06 beside it.
    from monitor.fleet.fleetview import code_groups, machine_view

    rows = [
        _row(
            "M06",
            1,
            "fault",
            2.0,
            [
                _ep("fault", 5.0, 30.0, "piston_wear", {"piston_wear": 40}),
                _ep("fault", 40.0, 50.0, "spool_wear", {"spool_wear": 10}, spn_fmi=SPOOL),
            ],
        )
    ]
    v = machine_view("M06", rows)
    assert v.alarms[1].what.endswith("the machine: piston seal suspected")
    groups, periods = code_groups([v])
    assert [(g.spn, g.fmi, g.what, g.machines) for g in groups] == [
        (*PISTON, "piston seal suspected", ["M06"]),
        (*SPOOL, "worn valve spool suspected", ["M06"]),
    ]
    assert periods == ["day 01"]
