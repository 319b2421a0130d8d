"""The whole-machine simulator (``monitor simulate --machine excavator4``): physics checked by
hand, and the CLI's files on dbc/excavator4.dbc.

Values used by hand below (config/excavator4_sim.yaml): pump 18 cc/rev x 2200 rpm = 39.6
L/min; LS margin 20 bar; rated section flows at full stroke and the margin: boom 24, stick
22, bucket 18, swing 14 L/min; swing motor 19.5 cc/rev x gear 80 = 1560 cc per house turn;
house J = 1000 kg x 0.75^2 + 240 = 802.5 kg m^2.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from monitor.cli import main
from monitor.codec.frames import FrameCodec
from monitor.io.candump import read_candump
from monitor.io.csvio import read_csv
from monitor.io.recording import Recording
from monitor.resources import resource_path
from monitor.sim.whole import kernel as K
from monitor.sim.whole.cycles import SPOOL_SIGNALS, make_whole_cycle
from monitor.sim.whole.faults import parse_machine_fault
from monitor.sim.whole.params import load_whole_machine, pack_params
from monitor.sim.whole.simulate import pack_inputs, rest_state, run_whole, simulate_whole

LPM = 1e-3 / 60.0
BAR = 1e5


@pytest.fixture(scope="module")
def machine():
    return load_whole_machine()


def _commands(duration_s: float, dt: float = 0.01, payload: float = 0.0, **spool_pct: float):
    t = np.arange(int(round(duration_s / dt)) + 1) * dt
    cols = {sig: np.full_like(t, spool_pct.get(loop, 0.0)) for loop, sig in SPOOL_SIGNALS.items()}
    cols["EngineSpeed"] = np.full_like(t, 2200.0)
    cols["OilTemp"] = np.full_like(t, 50.0)
    cols["Payload"] = np.full_like(t, payload)
    return Recording(t, cols, source="test commands")


def test_flow_sharing_under_saturation_scales_every_section_alike(machine):
    # Boom 100 %, stick 80 %, bucket 60 % extend: demand 24 + 17.6 + 10.8 = 52.4 L/min, above
    # the pump's 39.6 L/min less its healthy leakage (10 cc/min/bar x PP).  Post-compensated
    # (flow sharing): every section gets its demand x pump flow / 52.4 of it (about 0.746:
    # boom 17.9, stick 13.1, bucket 8.1 L/min); the pump at full displacement.  At every
    # instant the split is exact (one drop PP - PLS across every spool: shares 24/52.4 =
    # 0.4580, 0.3359, 0.2061), while the total rings about the pump's flow with the boom's
    # oscillation (the line's compliance), so over 0.4-1.0 s.
    trace = run_whole(_commands(1.0, boom=100, stick=80, bucket=60), machine)
    rows = slice(40, 101)  # 0.4-1.0 s: past the start's transient, before any end stop
    demand = {"boom": 24.0, "stick": 0.8 * 22.0, "bucket": 0.6 * 18.0}
    total = sum(trace.loop(loop, 2)[rows] for loop in demand)
    pump_lpm = 39.6 - 0.010 * trace.rec[rows, K.R_PP] / BAR
    factor = pump_lpm.mean() / sum(demand.values())
    for loop, want in demand.items():
        got = trace.loop(loop, 2)[rows]
        assert np.allclose(got / total, want / sum(demand.values()), rtol=1e-3), loop
        assert got.mean() / LPM == pytest.approx(want * factor, rel=0.015), loop
    assert np.allclose(trace.rec[rows, K.R_QP] / LPM, pump_lpm, rtol=1e-3)
    assert trace.loop("swing", 2)[rows].max() == 0.0


def test_a_held_load_stays(machine):
    # Closed spools, no leakage fault: every cylinder holds its gravity load (and a 150 kg
    # payload) where it is, the house does not turn, for 10 s.
    cmd = _commands(10.0, payload=150.0)
    trace = run_whole(cmd, machine)
    for loop in ("boom", "stick", "bucket", "swing"):
        x = trace.loop(loop, 3)
        assert np.ptp(x) < 1e-6, (loop, np.ptp(x))  # less than a micrometre (a microradian)
    assert np.allclose(trace.rec[:, K.R_PP] / BAR, 20.0, atol=0.1)  # standby


def test_closed_spools_drain_the_ls_line_and_the_pump_falls_to_standby(machine):
    # Every spool closed with the LS line at 118 bar and PP at 138 bar (a lift just ended).
    # By hand (config/excavator4_sim.yaml): the LS line drains through its bleed, laminar
    # 5 cc/min/bar = 8.333e-13 m^3/s/Pa, into 0.1 L of oil at 1.5 GPa: tau = 1e-4 / (1.5e9 x
    # 8.333e-13) = 0.080 s, PLS = 118 exp(-t / 0.08) bar.  The pump is destroked while PP >
    # PLS + 20 bar and leaks 10 cc/min/bar = 1.667e-12 m^3/s/Pa from its 1 L line: tau = 1e-3
    # / (1.5e9 x 1.667e-12) = 0.400 s, PP = 138 exp(-t / 0.4) bar (83.70 at 0.2 s, 50.77 at
    # 0.4 s, both above PLS + 20).  Then the regulator holds PP at standby: displacement
    # (20 bar - PP) / 5 bar x 6.6e-4 m^3/s = 1.667e-12 x PP, PP = 20 / (1 + 1.667e-12 x 5e5
    # / 6.6e-4) = 19.975 bar.
    prm = pack_params(machine)
    cmd = _commands(3.0)
    u = pack_inputs(cmd)
    y0 = rest_state(machine, prm, u[0])
    y0[K.S_PP] = 138 * BAR
    y0[K.S_LS] = 118 * BAR
    rec = K.integrate(y0, u, 50, 0.01, prm, 50)
    pls, pp = rec[:, K.R_LS] / BAR, rec[:, K.R_PP] / BAR
    for i in (4, 8, 16):
        assert pls[i] == pytest.approx(118 * math.exp(-i * 0.01 / 0.08), rel=1e-3), i
    for i in (20, 40):
        assert pp[i] == pytest.approx(138 * math.exp(-i * 0.01 / 0.4), rel=1e-3), i
    assert pp[-1] == pytest.approx(19.975, abs=0.002)


def test_a_lift_ended_leaves_the_pump_at_standby_not_at_the_load_pressure(machine):
    # The boom lifts 150 kg for 1 s, then every spool is closed: 1.5 s later PP is back at
    # standby (19.975 bar, as above; before the bleed it stayed at the lift's load pressure
    # plus the margin), while the boom holds its load (PA stays far above PP).
    cmd = _commands(2.5, payload=150.0, boom=100)
    cmd[SPOOL_SIGNALS["boom"]][cmd.t > 1.0] = 0.0
    trace = run_whole(cmd, machine)
    pp = trace.rec[:, K.R_PP] / BAR
    pa = trace.loop("boom", 0) / BAR
    assert pp[100] > 60.0  # lifting: the load pressure plus 20 bar
    assert pp[-1] == pytest.approx(19.975, abs=0.01)
    assert pa[-1] > 40.0


def test_a_neighbours_leak_leaves_the_shared_pp_alone_once_the_spools_close(machine):
    # Isolation at its source: the stick curls in for 1 s, then every spool closes.  With a
    # worn stick piston (severity 1) the stick's held chambers equalise through the seal, so
    # in the second after the stop its PA is far from the healthy run's (the healthy one
    # rings); PP, the signal every section model reads, is the standby pressure in both
    # (19.975 bar, as above), not the stick's last load pressure plus the margin, so the
    # boom's model is not handed the stick's fault.
    cmd = _commands(4.0, payload=150.0, stick=60)
    cmd[SPOOL_SIGNALS["stick"]][cmd.t > 1.0] = 0.0
    healthy = run_whole(cmd, machine)
    worn = run_whole(cmd, machine, [parse_machine_fault("stick.piston_wear:1")])
    gap = np.abs(worn.loop("stick", 0) - healthy.loop("stick", 0))[101:201] / BAR
    assert gap.max() > 5.0  # the fault is in the stick's own ports
    last = slice(-100, None)  # the last second
    for trace in (healthy, worn):
        assert np.allclose(trace.rec[last, K.R_PP] / BAR, 19.975, atol=0.01)


def test_swing_acceleration_is_torque_over_inertia(machine):
    # 100 bar across the motor, spools closed, house at rest: torque = 1560e-6 m^3/rev x 1e7 Pa
    # / (2 pi) = 2482.8 N m; alpha = 2482.8 / 802.5 = 3.094 rad/s^2; after 1 ms omega =
    # 3.094e-3 rad/s (leakage moves 0.08 bar and friction 0.04 % in that time).
    prm = pack_params(machine)
    cmd = _commands(0.001, dt=0.001)
    u = pack_inputs(cmd)
    y0 = rest_state(machine, prm, u[0])
    b = K.S0 + K.NS * K.SWING
    y0[b + K.X_PA] = 100 * BAR
    y0[b + K.X_PB] = 0.0
    trace = run_whole(cmd, machine, y0=y0, prm=prm)
    torque = 19.5e-6 * 80 * 100 * BAR / (2 * math.pi)
    inertia = 1000 * 0.75**2 + 240
    assert torque / inertia == pytest.approx(3.094, rel=1e-3)
    omega = trace.loop("swing", 4)[-1]
    assert omega / 0.001 == pytest.approx(torque / inertia, rel=5e-3)


@pytest.mark.parametrize("loop", ["boom", "stick", "bucket", "swing"])
def test_each_loop_steady_speed_is_its_flow_over_its_area(machine, loop):
    # One lever at 50 %, the others closed: v = Q / A_cap (extending cylinders), omega = Q /
    # (1560e-6 / 2 pi) for the house.  Q itself is about 0.5 x rated x sqrt(18.5 / 20): the LS
    # regulator's 5 bar band leaves the margin 1.5 bar short at 30 % of the pump's flow.
    duration = 3.0 if loop == "swing" else 1.0
    trace = run_whole(_commands(duration, **{loop: 50.0}), machine)
    rows = slice(-50, None)  # the last 0.5 s
    q = trace.loop(loop, 2)[rows]
    v = trace.loop(loop, 4)[rows]
    area = 19.5e-6 * 80 / (2 * math.pi) if loop == "swing" else machine.area_a_m2(loop)
    assert v.mean() == pytest.approx(q.mean() / area, rel=0.01)
    rated = {"boom": 24.0, "stick": 22.0, "bucket": 18.0, "swing": 14.0}[loop]
    assert q.mean() / LPM == pytest.approx(0.5 * rated * math.sqrt(18.5 / 20), rel=0.03)


def test_faults_name_their_loop_and_pump_wear_slows_a_saturated_machine(machine):
    assert parse_machine_fault("stick.piston_wear:0.5@10+5").label == "stick.piston_wear"
    for text, fragment in (
        ("swing.piston_wear:0.5", "not one of the swing loop's"),
        ("arm.spool_wear:0.5", "unknown loop"),
        ("pump_wear:0.5", "LOOP.FAULT"),
        ("pump.pump_wear:1.5", "outside 0..1"),
    ):
        with pytest.raises(Exception, match=fragment):
            parse_machine_fault(text)
    # Pump wear at 1 leaks 8.3e-12 m^3/(s Pa) x PP on top of the healthy 10 cc/min/bar
    # (1.667e-12).  Saturated (three levers full: 64 L/min asked of 39.6) the regulator has
    # no displacement left to make up for it: the pump delivers 39.6 L/min less the leaks
    # (the wear's about 2 L/min at 40 bar), and the sections share less.
    healthy_leak = 10e-6 / 60 / BAR
    cmd = _commands(1.0, boom=100, stick=100, bucket=100)
    healthy = run_whole(cmd, machine)
    worn = run_whole(cmd, machine, [parse_machine_fault("pump.pump_wear:1")])
    rows = slice(20, None)
    pp = worn.rec[rows, K.R_PP]
    pp_h = healthy.rec[rows, K.R_PP]
    assert np.allclose(healthy.rec[rows, K.R_QP], 39.6 * LPM - healthy_leak * pp_h, rtol=1e-6)
    assert np.allclose(
        worn.rec[rows, K.R_QP], 39.6 * LPM - (healthy_leak + 8.3e-12) * pp, rtol=1e-6
    )
    q_h = sum(healthy.loop(loop, 2) for loop in ("boom", "stick", "bucket"))[rows].mean()
    q_w = sum(worn.loop(loop, 2) for loop in ("boom", "stick", "bucket"))[rows].mean()
    assert q_w == pytest.approx(
        q_h - 8.3e-12 * pp.mean() - healthy_leak * (pp - pp_h).mean(), rel=0.01
    )


@pytest.mark.parametrize(
    "fault, loop", [("boom.spool_wear:1", "boom"), ("stick.piston_wear:1", "stick")]
)
def test_a_loop_fault_moves_its_own_held_load_only(machine, fault, loop):
    # Closed spools for 5 s: a worn boom spool lets the boom's held load (PA about 31 bar)
    # out through the A->T land's underlap of 0.1, so the boom sinks; the stick's piston leak
    # (5e-12 m^3/(s Pa) across the cylinder) lets it move.  The others move only as their
    # gravity load follows the changed pose (their oil's compression: 33 um of the stick
    # while the boom sinks 76 mm), under a fiftieth of the faulty loop's motion; the house
    # not at all.
    trace = run_whole(_commands(5.0), machine, [parse_machine_fault(fault)])
    own = np.ptp(trace.loop(loop, 3))
    assert own > 1e-3  # more than a millimetre
    for other in ("boom", "stick", "bucket", "swing"):
        if other != loop:
            assert np.ptp(trace.loop(other, 3)) < min(own / 50, 1e-4), other


def test_a_duty_cycle_is_seeded_and_moves_every_function(machine):
    a = make_whole_cycle("truck-loading", 60, 3, machine)
    b = make_whole_cycle("truck-loading", 60, 3, machine)
    for sig in SPOOL_SIGNALS.values():
        assert np.array_equal(a[sig], b[sig])
        assert (np.abs(a[sig]) > 30).any() and (a[sig] > 0).any() and (a[sig] < 0).any()
    assert a["DigForce"].max() > 0 and a["Payload"].max() > 0
    lift = make_whole_cycle("lifting", 120, 3, machine)
    assert (lift["SpoolCmd"] == 0).mean() > 0.5  # long holds and idling
    rec = simulate_whole(a, machine, seed=None)
    assert all(np.isfinite(rec[n]).all() for n in rec.columns)


def _lift_after_stick_s(rec: Recording) -> np.ndarray:
    """For each lift (the boom's command rising from 0 above 0), its start less the end of
    the stick's dig move around it (where the stick's command leaves its plateau), s."""
    t, boom, stick = rec.t, rec["SpoolCmd"], rec["Stick_SpoolCmd"]
    edges = np.diff((stick > 0).astype(int))
    starts, ends = np.flatnonzero(edges == 1) + 1, np.flatnonzero(edges == -1) + 1
    offsets = []
    for k in np.flatnonzero((boom[:-1] <= 0) & (boom[1:] > 0)) + 1:
        began = starts[starts < k]
        if not len(began):
            continue
        lo = int(began[-1])  # the last stick-in move begun before the lift
        hi = int(ends[ends > lo][0]) if (ends > lo).any() else len(t)
        move = stick[lo:hi]
        plateau_end = lo + int(np.flatnonzero(move == move.max())[-1])
        offsets.append(t[k] - t[plateau_end])
    return np.array(offsets)


def test_the_dig_lift_cycle_starts_the_lift_at_every_phase_of_the_stick_s_dig_end(machine):
    """`dig-lift` (training data) starts each lift 1.5 s before to 0.3 s after the stick's dig
    move ends, so a boom ramping up meets a stick still open; truck loading starts it within
    0.3 s of the dig's end (the later of the stick's and the bucket's), so rarely before the
    stick's; and it is not one of the operator's cycles (fleets draw from those)."""
    from monitor.sim.whole.cycles import TRAINING_CYCLES, WHOLE_CYCLES

    assert "dig-lift" in TRAINING_CYCLES and "dig-lift" not in WHOLE_CYCLES
    over = _lift_after_stick_s(make_whole_cycle("dig-lift", 600, 111, machine))
    assert len(over) > 25 and over.min() < -1.2 and (over >= -1.5 - 0.02).all()
    assert (over < -0.3).mean() > 0.5  # most lifts start with the stick still open
    assert ((over > -0.3) & (over < 0.3)).any()  # and some as it closes
    truck = _lift_after_stick_s(make_whole_cycle("truck-loading", 600, 111, machine))
    assert len(truck) > 25 and (truck > -0.3 - 0.02).all()


def test_the_return_to_stop_cycle_feathers_the_boom_down_onto_its_stop(machine):
    """`return-to-stop` (training data, not an operator's cycle) ends most boom lowerings
    with the lever feathered at 8-25 % (the returns; a lift's lowering runs at 20-40 %);
    truck loading's returns lower at 40-90 % and never feather."""
    from monitor.sim.whole.cycles import TRAINING_CYCLES, WHOLE_CYCLES

    assert "return-to-stop" in TRAINING_CYCLES and "return-to-stop" not in WHOLE_CYCLES

    def last_levels(rec: Recording) -> np.ndarray:
        """Each lowering's lever before its return (the return takes 0.5 s at most)."""
        boom = rec["SpoolCmd"]
        ends = np.flatnonzero(np.diff((boom < 0).astype(int)) == -1) + 1
        return boom[ends - 51]

    ours = last_levels(make_whole_cycle("return-to-stop", 600, 113, machine))
    feathered = (ours >= -25.0) & (ours <= -8.0)
    assert feathered.sum() >= 10 and feathered.mean() > 0.6
    truck = last_levels(make_whole_cycle("truck-loading", 600, 113, machine))
    assert len(truck) > 20 and (truck <= -40.0 + 1e-9).all()


def test_the_rest_on_stop_cycle_lets_the_boom_s_lever_go_as_the_rod_lands(machine, monkeypatch):
    """`rest-on-stop` (training data) lets the boom's lever go where the simulated rod lands,
    and the moment sets what the rod side traps for the rest on the stop: the return started
    at the landing holds the stall (the pump's cut-off, 200 bar less the section's drop),
    started earlier by a third of the return's time (0.075 s from 45 % at 200 %/s) it traps
    part of the rise, well below the stall and above the lowering pressure (26-47 bar while
    the rod moved), and started earlier by 0.6 of it the rod stops short of the stop."""
    from monitor.sim.whole import landing
    from monitor.sim.whole.cycles import TRAINING_CYCLES, WHOLE_CYCLES

    assert "rest-on-stop" in TRAINING_CYCLES and "rest-on-stop" not in WHOLE_CYCLES
    lowering = _commands(3.0, boom=-45.0)  # from 30 % of the stroke: lands after 1.4 s

    def released(early: float) -> tuple[float, float, float]:
        monkeypatch.setattr(landing, "RELEASE_EARLY", (early, early))
        cmd = landing.release_on_landing(lowering, machine, seed=1)
        trace = run_whole(cmd, machine)
        return (
            float(cmd["SpoolCmd"][-1]),
            float(trace.loop("boom", 3)[-1]),
            float(trace.loop("boom", 1)[-1] / BAR),
        )

    lever, rod_m, stall_bar = released(0.0)
    assert lever == 0.0 and rod_m <= landing.LANDED_M and stall_bar > 180.0
    lever, rod_m, part_bar = released(1 / 3)
    assert lever == 0.0 and rod_m <= landing.LANDED_M and 60.0 < part_bar < 0.8 * stall_bar
    _, rod_m, _ = released(0.6)
    assert rod_m > landing.LANDED_M  # the rod held on its cap side just above the stop


def _dbc_signals() -> list[str]:
    codec = FrameCodec.from_dbc(resource_path("dbc", "excavator4.dbc"))
    return [n for m in codec.messages.values() if m.name.startswith("HYD_") for n in m.signal_names]


def test_cli_writes_a_csv_with_the_dbc_names_and_a_log_the_dbc_decodes(tmp_path, capsys):
    csv, log = tmp_path / "whole.csv", tmp_path / "whole.log"
    args = [
        "simulate",
        "--machine",
        "excavator4",
        "--duration",
        "20",
        "--seed",
        "5",
        "--cycle",
        "truck-loading",
        "--fault",
        "stick.piston_wear:0.5@5",
    ]
    assert main([*args, "--out", str(csv)]) == 0
    assert main([*args, "--out", str(log)]) == 0
    rec = read_csv(csv)
    names = _dbc_signals()
    assert sorted(rec.columns) == sorted(set(names) - {"Swing_RodPos"})
    assert len(rec) == 2001
    codec = FrameCodec.from_dbc(resource_path("dbc", "excavator4.dbc"))
    seen: dict[str, list[float]] = {}
    for msg in read_candump(log):
        d = codec.decode_message(msg)
        assert d.values is not None and not d.counter_jump, d
        for k, v in d.values.items():
            seen.setdefault(k, []).append(v)
    assert codec.counts.rejected_total == 0 and codec.counts.counter_jumps == 0
    assert codec.counts.ignored == 0
    for name in rec.columns:
        got = np.array(seen[name])
        if name == "OilTemp":
            continue  # one frame a second
        assert len(got) == 2001, name
        assert np.allclose(got, rec[name], atol=0.006), name
    assert "excavator4" in capsys.readouterr().err


def test_cli_help_lists_the_machine_and_bad_machine_arguments_exit_2(tmp_path, capsys):
    assert main(["simulate", "--help"]) == 0
    text = capsys.readouterr().out
    for word in ("--machine", "excavator4", "truck-loading", "motor_leakage", "pump_wear"):
        assert word in text
    out = str(tmp_path / "x.csv")
    for args, fragment in (
        (["--cycle", "truck-loading"], "add --machine excavator4"),
        (["--machine", "excavator4", "--cycle", "boom"], "boom-loop cycle"),
        (["--machine", "excavator4", "--fault", "piston_wear:0.5"], "LOOP.FAULT"),
        (["--machine", "excavator4", "--duration", "7201"], "7200"),
    ):
        full = ["simulate", "--duration", "5", *args, "--out", out]
        assert main(full) == 2, args
        assert fragment in capsys.readouterr().err, args


def test_the_swing_stop_cycle_lets_short_fast_swings_go_to_centre(machine):
    """`swing-stop` (training data, not an operator's cycle) holds the swing's lever 0.8-3.5 s
    at 40-100 % and lets it go to centre in 0.2-0.6 s, never faster than the operator's
    200 %/s (so at least lever/200 s), a neighbour's lever let go within 0.6 s of it in most;
    truck loading holds the swing longer (a 90-180 degree swing)."""
    from monitor.sim.whole.cycles import TRAINING_CYCLES, WHOLE_CYCLES

    assert "swing-stop" in TRAINING_CYCLES and "swing-stop" not in WHOLE_CYCLES
    rec = make_whole_cycle("swing-stop", 300, 123, machine)
    swing = np.asarray(rec["Swing_SpoolCmd"])
    neighbours = np.abs(
        np.stack([rec[n] for n in ("SpoolCmd", "Stick_SpoolCmd", "Bucket_SpoolCmd")])
    )
    moving = np.abs(swing) > 1e-9
    starts = np.flatnonzero(np.diff(moving.astype(int)) == 1) + 1
    ends = np.flatnonzero(np.diff(moving.astype(int)) == -1) + 1
    quick = shared = 0
    for a in starts[starts < ends[-1]]:  # a swing still running at the end left out
        b = ends[ends > a][0]
        amp = np.abs(swing[a:b]).max()
        top = a + np.flatnonzero(np.abs(swing[a:b]) >= amp - 1e-9)
        held_s, release_s = (top[-1] - top[0]) * 0.01, (b - top[-1]) * 0.01
        if held_s > 3.5 + 0.02:
            continue  # a truck load's swing
        quick += 1
        assert 40.0 - 1e-9 <= amp <= 100.0 + 1e-9
        assert max(0.2, amp / 200.0) - 0.02 <= release_s <= 0.6 + 0.02, (amp, release_s)
        let_go = np.flatnonzero(
            np.diff((neighbours[:, b - 80 : b + 80] > 1e-9).any(axis=0).astype(int)) < 0
        )
        shared += bool(let_go.size)
    assert quick >= 20 and shared / quick > 0.5
