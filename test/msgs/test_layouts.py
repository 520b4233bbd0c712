"""The graph's message layouts: what the nodes publish parses back to the same values; bad content is refused."""
import math

import pytest

from mwip_ros.core.controller import ControlOutput
from mwip_ros.core.model import State
from mwip_ros.msgs import BadMessage, CdrError, MessageError, cdr
from mwip_ros.msgs import layouts as L
from mwip_ros.msgs.stamps import join_ns, split_ns, stamp_ns, to_time

pytestmark = pytest.mark.unit


def test_state_round_trip_names_the_joints_and_carries_the_previous_command():
    x = State(0.5, -0.1745, 1.25, -2.5)
    data = L.encode_state(5_000_000, x, 12.5)
    stamp, frame, names, pos, vel, eff = cdr.decode_joint_state(data)
    assert (names, pos, vel, eff) == (list(L.JOINT_NAMES), (0.5, -0.1745), (1.25, -2.5), (12.5, 0.0))
    stamp, got, u_prev = L.parse_joint_state(data)
    assert (stamp, got, u_prev) == (5_000_000, x, 12.5) and isinstance(got, State)


def test_joints_are_found_by_name_whatever_their_order():
    enc = cdr.JointStateEncoder(("body_pitch", "wheel"))
    _, x, u_prev = L.parse_joint_state(enc(7, (-0.2, 3.0), (0.4, 1.5), (0.0, 9.0)))
    assert x == State(3.0, -0.2, 1.5, 0.4) and u_prev == 9.0


@pytest.mark.parametrize("data, words", [
    (L.encode_state(1, State(0.0, math.nan, 0.0, 0.0), 0.0), "non-finite joint state"),
    (L.encode_state(1, State(0.0, 0.0, 0.0, 0.0), math.inf), "non-finite joint state"),
    (cdr.JointStateEncoder(("left", "right"))(1, (0.0, 0.0), (0.0, 0.0), (0.0, 0.0)), "joint names"),
    (cdr.JointStateEncoder(L.JOINT_NAMES)(1, (0.0,), (0.0, 0.0), (0.0, 0.0)), "array lengths"),
    (b"\x00\x01\x00\x00\x01", "not a sensor_msgs/JointState"),
])
def test_bad_states_are_refused_with_the_reason(data, words):
    with pytest.raises(BadMessage, match=words):
        L.parse_joint_state(data)


def test_wrench_command_clock_and_internals():
    assert L.parse_wrench(L.encode_wrench(42, 1.5, -2.5)) == (42, 1.5, -2.5)
    assert L.parse_command(L.encode_command(-3.25)) == -3.25
    assert L.parse_clock(L.encode_clock(10 ** 9 + 5)) == 10 ** 9 + 5
    out = ControlOutput(u=1.0, u_dsc=2.0, u_taud=3.0, S1=4.0, S2=5.0, x1=6.0, x4_bar=7.0, x4d=8.0)
    stamp, values = L.parse_internals(L.encode_internals(9, out))
    assert stamp == 9 and values == {n: getattr(out, n) for n in L.INTERNAL_NAMES}
    with pytest.raises(BadMessage, match="non-finite command"):
        L.parse_command(L.encode_command(math.nan))
    with pytest.raises(BadMessage, match="non-finite torque"):
        L.parse_wrench(L.encode_wrench(1, math.nan, 0.0))
    with pytest.raises(BadMessage, match="not a std_msgs/Float64"):
        L.parse_command(b"\x00\x01")


def test_stamps_convert_both_ways_and_refuse_what_time_cannot_hold():
    for ns in (0, 1, 999_999_999, 1_000_000_000, 5 * 10 ** 9 + 7, -1):
        sec, nsec = split_ns(ns)
        assert 0 <= nsec < 10 ** 9 and join_ns(sec, nsec) == ns == stamp_ns(to_time(ns))
    with pytest.raises(CdrError, match="int32"):
        split_ns(2 ** 31 * 10 ** 9)
    assert issubclass(CdrError, MessageError) and issubclass(BadMessage, MessageError)
