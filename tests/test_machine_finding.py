"""The machine's finding (monitor.detection.machine): which of a machine's alarms names
the fault, on hand-made alarm sequences."""

from __future__ import annotations

from monitor.detection.machine import Alarm, MachineFinding, decide, finding_of


def test_the_first_loop_names_and_later_loops_are_secondary() -> None:
    # Boom spool wear at 0.5 raised the boom, and the swing 413 s in (the session's case).
    f = finding_of([Alarm("swing", 413.0, 1.2), Alarm("boom", 150.0, 3.0)])
    assert (f.named, f.t_s, f.secondary, f.explained) == ("boom", 150.0, ["swing"], [])


def test_alarms_within_a_second_are_named_by_the_stronger_evidence() -> None:
    f = decide([Alarm("stick", 200.0, 1.1), Alarm("bucket", 200.6, 4.0)])
    assert f.named == "bucket" and f.secondary == ["stick"]
    apart = decide([Alarm("stick", 200.0, 1.1), Alarm("bucket", 201.5, 4.0)])
    assert apart.named == "stick"


def test_the_pump_explains_the_loops_that_alarmed_after_its_window_began() -> None:
    alarms = [
        Alarm("boom", 90.0, 2.0),  # before the pump's window: not the pump's doing
        Alarm("stick", 140.0, 1.5),
        Alarm("pump", 180.0, 1.3, since_s=130.0),
        Alarm("swing", 200.0, 1.1),
    ]
    f = finding_of(alarms)
    assert f.named == "pump" and f.t_s == 180.0
    assert f.explained == ["stick", "swing"] and f.secondary == ["boom"]


def test_the_finding_changes_only_when_it_says_something_new_and_ends_with_the_alarms() -> None:
    mf = MachineFinding()
    assert mf.raised(Alarm("boom", 10.0, 2.0))
    assert mf.raised(Alarm("stick", 20.0, 2.0))  # a secondary alarm is news
    assert not mf.cleared("boom")  # the stick's alarm is still up
    assert mf.finding.named == "boom"  # the episode's first alarm still names
    assert mf.cleared("stick")  # all clear: the finding is none
    assert mf.finding.named is None
    assert mf.raised(Alarm("stick", 99.0, 2.0)) and mf.finding.named == "stick"
