"""mwip_ros.bag.segments: a recording's state stream split into runs where its stamps go back."""
import pytest

from mwip_ros.bag import BagWriter, raw_messages
from mwip_ros.bag.segments import Segments, recorded_messages, split
from mwip_ros.core.plants.model import State
from mwip_ros.msgs import layouts as L

pytestmark = pytest.mark.unit

H = 5_000_000
JS, EST, CMD, TRUTH = ("sensor_msgs/msg/JointState", "geometry_msgs/msg/WrenchStamped", "std_msgs/msg/Float64",
                       "geometry_msgs/msg/WrenchStamped")
X = State(0.0, -0.1745, 0.0, 0.0)


def _stream(stamps):
    """(position, log time, stamp): one message per stamp, 1 ms apart."""
    return [(i, i * 1_000_000, s) for i, s in enumerate(stamps)]


def _states(segs):
    return [s.states for s in segs]


def test_resends_stay_in_the_run_and_each_stamp_that_goes_back_starts_one():
    run1 = [k * H for k in range(10)] + [9 * H, 9 * H]          # the last state resent twice
    run2 = [0, 0, 0] + [k * H for k in range(1, 5)]             # a lockstep reset: state 0 resent until followed
    run3 = [0] + [k * H for k in range(1, 3)]
    segs, strays = split(_stream(run1 + run2 + run3))
    assert _states(segs) == [10, 5, 3] and not strays
    assert [s.resends for s in segs] == [2, 2, 0]
    assert [(s.first_stamp, s.last_stamp) for s in segs] == [(0, 9 * H), (0, 4 * H), (0, 2 * H)]
    assert [s.first_index for s in segs] == [0, 12, 19] and segs[0].last_index == 11
    assert segs[1].first_log_time == 12_000_000 and segs[1].last_log_time == 18_000_000


def test_a_realtime_reset_goes_back_to_the_runs_start_and_a_reset_after_one_period_still_shows():
    t0 = 1_796_000_000_000_000_000   # realtime: the clock's time
    run1 = [t0 + k * H for k in range(2400)]
    run2 = [t0, t0 + H]                                          # reset after one period
    run3 = [t0 + k * H for k in range(1022)]
    segs, strays = split(_stream(run1 + run2 + run3))
    assert _states(segs) == [2400, 2, 1022] and not strays
    assert segs[0].duration_s == pytest.approx(11.995)


def test_a_stray_state_splits_nothing_thrown_back_or_ahead():
    stream = [k * H for k in range(100)] + [3 * H] + [k * H for k in range(100, 110)]        # one thrown back
    segs, strays = split(_stream(stream))
    assert _states(segs) == [110] and [s for _, s in strays] == [3 * H]
    stream = [k * H for k in range(100)] + [10 ** 15] + [k * H for k in range(100, 110)]     # one thrown ahead
    segs, strays = split(_stream(stream))
    assert _states(segs) == [110] and [s for _, s in strays] == [10 ** 15]
    # a real reset right after a stray is still a reset
    stream = [k * H for k in range(50)] + [10 ** 15] + [k * H for k in range(50, 60)] + [k * H for k in range(30)]
    segs, strays = split(_stream(stream))
    assert _states(segs) == [60, 30] and len(strays) == 1


def _write_spliced(bag, log_restarts: bool):
    """Run 1: states 0..k1 with their answers (estimate, truth, command), then a reset: run 2 under the same
    stamps, its state 0 resent twice.  ``log_restarts``: the recorder ran under use_sim_time (its log time is
    /clock, which restarts with the stamps)."""
    k1, k2 = 40, 25
    with BagWriter(bag) as w:
        for topic, t in (("/joint_states", JS), ("/disturbance_estimate", EST), ("/lumped_disturbance", TRUTH),
                         ("/wheel_torque_cmd", CMD)):
            w.add_topic(topic, t)
        wall = 10 ** 9
        for run, n in ((1, k1), (2, k2)):
            for k in range(n + 1):
                s = k * H
                for i, (topic, data) in enumerate(
                        [("/joint_states", L.encode_state(s, X, 0.0))] * (3 if run == 2 and k == 0 else 1)
                        + [("/disturbance_estimate", L.encode_wrench(s, float(run), 0.0)),
                           ("/lumped_disturbance", L.encode_wrench(s, float(run), 0.0)),
                           ("/wheel_torque_cmd", L.encode_command(float(run)))]):
                    wall += 1000
                    w.write(topic, data, s + i if log_restarts else wall)
    return k1, k2


def _write_late_answers(bag):
    """As _write_spliced, with run 1's answers to its last state recorded after run 2's state 0."""
    k1, k2 = 40, 25
    with BagWriter(bag) as w:
        for topic, t in (("/joint_states", JS), ("/disturbance_estimate", EST), ("/wheel_torque_cmd", CMD)):
            w.add_topic(topic, t)
        lt = 10 ** 9
        for k in range(k1 + 1):
            lt += 1000
            w.write("/joint_states", L.encode_state(k * H, X, 0.0), lt)
            if k < k1:
                w.write("/disturbance_estimate", L.encode_wrench(k * H, 1.0, 0.0), lt + 1)
                w.write("/wheel_torque_cmd", L.encode_command(1.0), lt + 2)
        for k in range(k2 + 1):
            lt += 1000
            w.write("/joint_states", L.encode_state(k * H, X, 0.0), lt)
            if k == 0:   # run 1's last answers, late
                w.write("/disturbance_estimate", L.encode_wrench(k1 * H, 1.0, 0.0), lt + 1)
                w.write("/wheel_torque_cmd", L.encode_command(1.0), lt + 2)
            w.write("/disturbance_estimate", L.encode_wrench(k * H, 2.0, 0.0), lt + 3)
            w.write("/wheel_torque_cmd", L.encode_command(2.0), lt + 4)
    return k1, k2


@pytest.mark.parametrize("log_restarts", [False, True], ids=["wall-clock recorder", "sim-time recorder"])
def test_a_spliced_bag_splits_in_recording_order_whatever_the_recorders_clock(tmp_path, log_restarts):
    bag = tmp_path / "bag"
    k1, k2 = _write_spliced(bag, log_restarts)
    segs = Segments.from_bag(bag)
    assert segs.spliced and _states(segs) == [k1 + 1, k2 + 1], segs.describe()
    assert [s.resends for s in segs] == [0, 2]
    counts = segs.count_topics()
    assert counts[0] == {"/joint_states": k1 + 1, "/disturbance_estimate": k1 + 1, "/lumped_disturbance": k1 + 1,
                         "/wheel_torque_cmd": k1 + 1}
    assert counts[1] == {"/joint_states": k2 + 3, "/disturbance_estimate": k2 + 1, "/lumped_disturbance": k2 + 1,
                         "/wheel_torque_cmd": k2 + 1}
    second = list(segs.select(-1))
    assert all(L.parse_wrench(d)[1] == 2.0 for _, t, d in second if t == "/disturbance_estimate")
    assert "2 run(s) in one recording" in segs.describe() and "segment 1: 26 states" in segs.describe()
    assert "choose one (segment=N)" in segs.refusal("mwip_report")
    if log_restarts:   # log-time order interleaves the runs: the reason for recording order
        by_log_time = Segments.from_messages(raw_messages(bag))
        assert _states(by_log_time) != [k1 + 1, k2 + 1]


def test_an_answer_recorded_after_the_next_run_began_counts_for_the_run_it_answers(tmp_path):
    bag = tmp_path / "bag"
    k1, k2 = _write_late_answers(bag)
    segs = Segments.from_bag(bag)
    assert _states(segs) == [k1 + 1, k2 + 1]
    est = [(seg, L.parse_wrench(d)) for seg, _lt, t, d in segs.tag(recorded_messages(bag))
           if t == "/disturbance_estimate"]
    assert all(value == seg + 1 for seg, (_stamp, value, _) in est)   # the late estimate for k1 in run 1
    assert sum(1 for seg, _ in est if seg == 0) == k1 + 1


def test_a_single_run_is_one_segment_and_a_bag_without_states_none(tmp_path):
    bag = tmp_path / "one"
    with BagWriter(bag) as w:
        w.add_topic("/joint_states", JS)
        for k in range(30):
            w.write("/joint_states", L.encode_state(k * H, X, 0.0), 10 ** 9 + k)
    segs = Segments.from_bag(bag)
    assert not segs.spliced and _states(segs) == [30]
    empty = tmp_path / "empty"
    with BagWriter(empty) as w:
        w.add_topic("/wheel_torque_cmd", CMD)
        w.write("/wheel_torque_cmd", L.encode_command(0.0), 10 ** 9)
    assert len(Segments.from_bag(empty)) == 0
