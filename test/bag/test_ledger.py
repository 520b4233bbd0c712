"""The ledger of a lockstep recording: one message per state on every topic of the loop, or the gaps named."""
import subprocess
import sys

import pytest

from mwip_ros.bag import BagWriter
from mwip_ros.bag.ledger import GAPS_KEY, Ledger
from mwip_ros.core.plants.model import State
from mwip_ros.msgs import layouts as L

pytestmark = pytest.mark.unit

H = 5_000_000
JS, CLOCK, EST, CMD = ("sensor_msgs/msg/JointState", "rosgraph_msgs/msg/Clock", "geometry_msgs/msg/WrenchStamped",
                       "std_msgs/msg/Float64")


def _run(ledger, states, skip=(), resend=(), start=0):
    for k in range(start, states):
        s = k * H
        for _ in range(2 if k in resend else 1):
            ledger.add("/joint_states", JS, L.encode_state(s, State(0.0, 0.0, 0.0, 0.0), 0.0))
            ledger.add("/clock", CLOCK, L.encode_clock(s))
        if ("est", k) not in skip:
            ledger.add("/disturbance_estimate", EST, L.encode_wrench(s, 1.0, 2.0))
        if ("cmd", k) not in skip:
            ledger.add("/wheel_torque_cmd", CMD, L.encode_command(1.0))


def test_a_complete_run_with_a_resend_has_no_gaps():
    led = Ledger()
    _run(led, 50, resend={0})
    assert led.gaps() == [] and led.repeats == {"/joint_states": 1, "/clock": 1}
    assert len(led.expected()) == 50


def test_missing_messages_are_named_with_the_first_missing_stamp():
    led = Ledger()
    _run(led, 50, skip={("est", 7), ("est", 30), ("cmd", 49)})
    assert led.gaps() == [("/disturbance_estimate", 48, 50, 7 * H), ("/wheel_torque_cmd", 49, 50, None)]
    assert led.gaps_text() == ("/disturbance_estimate: 48 of 50, first missing stamp t = 0.035 s; "
                               "/wheel_torque_cmd: 49 of 50")


def test_a_recorder_that_joined_late_misses_the_start_everywhere_and_says_so():
    led = Ledger()
    _run(led, 50, start=10)
    gaps = led.gaps()
    assert [g[0] for g in gaps] == ["/clock", "/disturbance_estimate", "/joint_states", "/wheel_torque_cmd"]
    assert all(g[1] == 40 and g[2] == 50 for g in gaps) and gaps[0][3] == 0


def test_without_clock_and_off_the_grid_from_0_it_is_not_a_lockstep_run():
    """A realtime plant's stamps start at its clock's time: no grid from 0, nothing judged (a partial graph there
    is a user's choice, not a gap)."""
    led = Ledger()
    led.counts.update({"/wheel_torque_cmd": 0, "/clock": 0})   # subscribed, nothing came
    start = 1_764_990_000_123_456_789   # a node clock's time [ns]
    for k in range(5):
        led.add("/joint_states", JS, L.encode_state(start + k * H, State(0, 0, 0, 0), 0.0))
    assert not led.lockstep() and led.gaps() == []


def test_a_recorder_that_never_heard_the_plant_judges_the_answers_stamps_and_names_the_plants_topics():
    """The recorder started last missed the plant's whole run (its discovery came too late: CI once), but recorded
    every answer: the estimates' stamps on the grid from 0 make it a lockstep recording, and /clock and
    joint_states, subscribed with nothing, are its gaps."""
    led = Ledger()
    led.counts.update({"/joint_states": 0, "/clock": 0})   # subscribed, nothing came
    for k in range(50):
        led.add("/disturbance_estimate", EST, L.encode_wrench(k * H, 1.0, 2.0))
        led.add("/wheel_torque_cmd", CMD, L.encode_command(1.0))
    assert led.lockstep()
    assert led.gaps() == [("/clock", 0, 50, None), ("/joint_states", 0, 50, None)]
    complete = Ledger()
    _run(complete, 50)
    assert complete.lockstep() and complete.gaps() == []


def test_past_its_stamp_limit_a_ledger_judges_nothing(monkeypatch):
    import mwip_ros.bag.ledger as ledger_module
    monkeypatch.setattr(ledger_module, "MAX_STAMPS", 20)
    led = Ledger()
    _run(led, 50, skip={("est", 7)})   # 30 stamps per topic not kept: any "gap" would be false
    assert led.overflow and led.gaps() == [] and led.counts["/joint_states"] == 50


@pytest.mark.cli
def test_the_report_shows_the_gaps_of_a_flagged_bag(tmp_path):
    bag = tmp_path / "flagged"
    with BagWriter(bag, custom_data={GAPS_KEY: "/disturbance_estimate: 48 of 50"}) as w:
        w.add_topic("/joint_states", JS)
        for k in range(50):
            w.write("/joint_states", L.encode_state(k * H, State(0.0, 0.0, 0.0, 0.0), 0.0), 10 ** 9 + k * H)
    r = subprocess.run([sys.executable, "-m", "mwip_ros.cli.report", str(bag), "--out", str(tmp_path / "rep"),
                        "--window", "0", "0.2"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert "incomplete lockstep recording" in r.stderr and "/disturbance_estimate: 48 of 50" in r.stderr
    assert "/disturbance_estimate: 48 of 50" in (tmp_path / "rep" / "metrics.md").read_text()


def test_an_expected_topic_with_nothing_recorded_is_a_gap_and_an_absent_optional_one_is_not():
    led = Ledger()
    led.counts.update({"/wheel_torque_cmd": 0, "/true_joint_states": 0})   # what a recorder expects
    for k in range(20):
        led.add("/joint_states", JS, L.encode_state(k * H, State(0.0, 0.0, 0.0, 0.0), 0.0))
        led.add("/clock", CLOCK, L.encode_clock(k * H))
    assert led.gaps() == [("/wheel_torque_cmd", 0, 20, None)]   # never subscribed: flagged, not forgotten
    for k in range(5):   # the plant measured with noise: its truth is judged like any loop topic
        led.add("/true_joint_states", JS, L.encode_state(k * H, State(0.0, 0.0, 0.0, 0.0), 0.0))
    assert [g[0] for g in led.gaps()] == ["/true_joint_states", "/wheel_torque_cmd"]


def test_a_ledger_keeps_runs_of_stamps_not_every_stamp():
    """The recorder's ledger must not grow with the recording: a topic's stamps on the grid are one run, each gap
    starts another; the judgement is the same as with every stamp kept."""
    led = Ledger()
    _run(led, 20_000, skip={("est", 7), ("est", 12_345)})
    assert led.stamps["/joint_states"].runs() == 1 and led.stamps["/clock"].runs() == 1
    assert led.stamps["/disturbance_estimate"].runs() == 3 and len(led.stamps["/disturbance_estimate"]) == 19_998
    assert led.gaps() == [("/disturbance_estimate", 19_998, 20_000, 7 * H)]
    assert list(led.stamps["/disturbance_estimate"])[:8] == [k * H for k in (0, 1, 2, 3, 4, 5, 6, 8)]
