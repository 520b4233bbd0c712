"""The graph's message layouts: what the nodes publish parses back to the same values; bad content is refused."""
import math

import pytest

from mwip_ros.core.control.controller import ControlOutput
from mwip_ros.core.plants.model import State
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


# --- the raw sensors' topics (docs/theory.md 6.4): imu/data_raw, wheel_encoder ---------------------------------------

def test_imu_round_trip_says_it_has_no_orientation():
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import Imu
    data = L.encode_imu(5_000_000, 0.125, -1.5, 9.75, gyro_variance=1.6e-5, accel_variance=4e-4)
    assert L.parse_imu(data) == (5_000_000, 0.125, -1.5, 9.75)
    m = deserialize_message(data, Imu)
    assert m.header.frame_id == L.IMU_FRAME == "imu_link"
    assert (m.orientation.x, m.orientation.y, m.orientation.z, m.orientation.w) == (0.0, 0.0, 0.0, 0.0)
    assert list(m.orientation_covariance) == [-1.0] + [0.0] * 8          # REP-145: no orientation
    assert (m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z) == (0.0, 0.125, 0.0)
    assert (m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z) == (-1.5, 0.0, 9.75)
    assert list(m.angular_velocity_covariance) == [1.6e-5, 0, 0, 0, 1.6e-5, 0, 0, 0, 1.6e-5]
    assert list(m.linear_acceleration_covariance) == [4e-4, 0, 0, 0, 4e-4, 0, 0, 0, 4e-4]


def test_encoder_round_trip():
    data = L.encode_encoder(7, 0.25, -3.5, 42.0)
    assert cdr.decode_joint_state(data)[1:] == (L.ENCODER_FRAME, ["wheel"], (0.25,), (-3.5,), (42.0,))
    assert L.ENCODER_FRAME == ""   # as plant_sim publishes it (a joint's state is in no frame)
    assert L.parse_encoder(data) == (7, 0.25, -3.5, 42.0)


def _imu(w=(0.0, 0.1, 0.0), a=(0.0, 0.0, 9.81), orientation_cov=(-1.0,) + (0.0,) * 8, q=(0.0,) * 4):
    return cdr.ImuEncoder("imu_link")(1, q, orientation_cov, w, (0.0,) * 9, a, (0.0,) * 9)


def test_an_imu_that_gives_an_orientation_is_not_an_error():
    """orientation_covariance[0] != -1 (a fused IMU) is read all the same: the estimators never read it."""
    assert L.parse_imu(_imu(orientation_cov=(0.01,) * 9, q=(0.0, 0.05, 0.0, 1.0))) == (1, 0.1, 0.0, 9.81)
    assert L.parse_imu(_imu(q=(math.nan,) * 4)) == (1, 0.1, 0.0, 9.81)   # what is not read is not judged


@pytest.mark.parametrize("data, words", [
    (_imu(w=(0.0, math.nan, 0.0)), "non-finite IMU reading"),
    (_imu(w=(math.inf, 0.0, 0.0)), "non-finite IMU reading"),     # every axis, the unused ones too
    (_imu(a=(0.0, 0.0, -math.inf)), "non-finite IMU reading"),
    (_imu(w=(0.0, 1001.0, 0.0)), "implausible angular_velocity 1001"),
    (_imu(w=(0.0, 0.0, -2e3)), "implausible angular_velocity"),
    (_imu(a=(1.5e3, 0.0, 9.81)), "implausible linear_acceleration 1500"),
    (_imu()[:-30], "not a sensor_msgs/Imu: message ends"),
    (b"\x00\x01\x00\x00" + bytes(8), "not a sensor_msgs/Imu"),
    (cdr.ImuEncoder("base_link")(1, (0.0,) * 4, (-1.0,) + (0.0,) * 8, (0.0,) * 3, (0.0,) * 9, (0.0, 0.0, 9.81),
                                 (0.0,) * 9), "frame_id 'base_link', expected 'imu_link'"),   # issue 30: accepted
    (cdr.ImuEncoder("")(1, (0.0,) * 4, (-1.0,) + (0.0,) * 8, (0.0,) * 3, (0.0,) * 9, (0.0, 0.0, 9.81), (0.0,) * 9),
     "frame_id '', expected 'imu_link'"),
])
def test_bad_imu_samples_are_refused_with_the_reason(data, words):
    with pytest.raises(BadMessage, match=words):
        L.parse_imu(data)


def test_the_raw_limits_are_the_documented_bounds():
    assert L.parse_imu(_imu(w=(1e3, -1e3, 1e3), a=(-1e3, 1e3, 1e3)))[1:] == (-1e3, -1e3, 1e3)   # on the bound: kept
    assert L.RAW_LIMITS == {"gyro": 1e3, "accel": 1e3, "phi": 1e9, "rate": 1e3, "torque": 1e6}
    assert L.parse_encoder(L.encode_encoder(1, -1e9, 1e3, -1e6))[1:] == (-1e9, 1e3, -1e6)


@pytest.mark.parametrize("data, words", [
    (cdr.JointStateEncoder(("left",))(1, (0.0,), (0.0,), (0.0,)), r"joint names \['left'\], expected \['wheel'\]"),
    (cdr.JointStateEncoder(L.JOINT_NAMES)(1, (0.0, 0.0), (0.0, 0.0), (0.0, 0.0)), "joint names"),
    (cdr.JointStateEncoder(("wheel",))(1, (0.0,), (), (0.0,)), "array lengths"),
    (cdr.JointStateEncoder(("wheel",))(1, (0.0, 1.0), (0.0,), (0.0,)), "array lengths"),
    (L.encode_encoder(1, math.nan, 0.0, 0.0), "non-finite encoder reading"),
    (L.encode_encoder(1, 0.0, 0.0, math.inf), "non-finite encoder reading"),
    (L.encode_encoder(1, 2e9, 0.0, 0.0), "implausible encoder angle"),
    (L.encode_encoder(1, 0.0, -1e4, 0.0), "implausible encoder rate"),
    (L.encode_encoder(1, 0.0, 0.0, 1e7), "implausible effort"),
    (L.encode_encoder(1, 0.0, 0.0, 0.0)[:-4], "not a sensor_msgs/JointState"),
    (L.encode_imu(1, 0.0, 0.0, 9.81), "not a sensor_msgs/JointState|joint names|frame_id"),   # another type's bytes
    (cdr.JointStateEncoder(("wheel",), "imu_link")(1, (0.0,), (0.0,), (0.0,)), "frame_id 'imu_link', expected ''"),
    (cdr.JointStateEncoder(("wheel",), "base_link")(1, (0.0,), (0.0,), (0.0,)), "frame_id 'base_link'"),
])
def test_bad_encoder_samples_are_refused_with_the_reason(data, words):
    with pytest.raises(BadMessage, match=words):
        L.parse_encoder(data)


def test_check_state_is_what_parse_joint_state_accepts():
    L.check_state(State(0.0, 3.0, 999.0, -999.0), 1e6)
    for x, u, words in ((State(0.0, 3.2, 0.0, 0.0), 0.0, "implausible theta_b"),
                        (State(0.0, 0.0, math.nan, 0.0), 0.0, "non-finite joint state"),
                        (State(0.0, 0.0, 0.0, 0.0), 2e6, "implausible effort")):
        with pytest.raises(BadMessage, match=words):
            L.check_state(x, u)
        with pytest.raises(BadMessage, match=words):
            L.parse_joint_state(L.encode_state(1, x, u))


def test_the_yaw_joint_and_the_two_torques():
    """docs/graph.md: a spatial plant's joint_states has a third joint 'yaw' (velocity = the gyro's yaw rate), which
    the planar parsers skip; wheel_torques_cmd is [wheel_left_joint, wheel_right_joint] with effort [u_L, u_R]."""
    import math as _m
    data = L.encode_state(7, (0.5, -0.1, 1.25, -2.5), 12.5, 0.75)
    stamp, x, u = L.parse_joint_state(data)
    assert (stamp, tuple(x), u) == (7, (0.5, -0.1, 1.25, -2.5), 12.5)
    assert L.parse_yaw_rate(data) == 0.75
    assert L.parse_yaw_rate(L.encode_state(7, (0.5, -0.1, 1.25, -2.5), 12.5)) is None
    with pytest.raises(BadMessage, match="yaw rate"):
        L.parse_yaw_rate(L.encode_state(7, (0.5, -0.1, 1.25, -2.5), 12.5, _m.nan))
    assert L.parse_wheel_torques(L.encode_wheel_torques(9, -3.0, 4.5)) == (9, -3.0, 4.5)
    for bad, why in ((cdr.JointStateEncoder(("wheel_right_joint", "wheel_left_joint"))(1, (), (), (1.0, 2.0)),
                      "joint names"),
                     (cdr.JointStateEncoder(L.WHEEL_TORQUE_JOINTS)(1, (), (), (1.0,)), "expected 2"),
                     (L.encode_wheel_torques(1, _m.inf, 0.0), "finite"),
                     (L.encode_wheel_torques(1, 0.0, 1e9), "implausible")):
        with pytest.raises(BadMessage, match=why):
            L.parse_wheel_torques(bad)
