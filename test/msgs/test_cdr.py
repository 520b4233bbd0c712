"""mwip_ros.msgs.cdr against rclpy's own serializer: both directions, many shapes, and bad bytes."""
import itertools
import math
import struct

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import WrenchStamped
from rclpy.serialization import deserialize_message, serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from mwip_ros.msgs import cdr

pytestmark = pytest.mark.unit

RNG = np.random.default_rng(7)
NAME_SETS = [(), ("wheel",), ("wheel", "body_pitch"), ("S1", "S2", "x4d", "x4_bar", "u_dsc", "u_taud", "u", "x1"),
             ("ä", "", "a" * 13)]


def _floats(n):
    return [float(x) for x in RNG.normal(0, 100, size=n)]


def _stamp():
    return int(RNG.integers(0, 2 ** 31 - 1)) * 1_000_000_000 + int(RNG.integers(0, 999_999_999))


@pytest.mark.parametrize("names,frame", list(itertools.product(NAME_SETS, ["", "b", "base_link"])))
def test_joint_state_both_ways(names, frame):
    enc = cdr.JointStateEncoder(names, frame)
    for n_pos, n_vel, n_eff in itertools.product((0, 1, 2, 3), repeat=3):
        stamp, pos, vel, eff = _stamp(), _floats(n_pos), _floats(n_vel), _floats(n_eff)
        # ours -> rclpy
        m = deserialize_message(enc(stamp, pos, vel, eff), JointState)
        assert (m.header.stamp.sec * 10 ** 9 + m.header.stamp.nanosec, m.header.frame_id) == (stamp, frame)
        assert (list(m.name), list(m.position), list(m.velocity), list(m.effort)) == (list(names), pos, vel, eff)
        # rclpy -> ours
        m = JointState(name=list(names), position=pos, velocity=vel, effort=eff)
        m.header.stamp, m.header.frame_id = Time(sec=stamp // 10 ** 9, nanosec=stamp % 10 ** 9), frame
        assert cdr.decode_joint_state(serialize_message(m)) == (stamp, frame, list(names), tuple(pos), tuple(vel),
                                                                 tuple(eff))


@pytest.mark.parametrize("frame", ["", "a", "abc", "odom_frame"])
def test_wrench_stamped_both_ways(frame):
    for _ in range(20):
        stamp, f, t = _stamp(), tuple(_floats(3)), tuple(_floats(3))
        m = deserialize_message(cdr.WrenchStampedEncoder(frame)(stamp, f, t), WrenchStamped)
        assert m.header.stamp.sec * 10 ** 9 + m.header.stamp.nanosec == stamp and m.header.frame_id == frame
        w = m.wrench
        assert (w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y, w.torque.z) == f + t
        assert cdr.decode_wrench_stamped(serialize_message(m)) == (stamp, frame, f, t)


def test_float64_and_clock_both_ways():
    for x in _floats(20) + [0.0, -0.0, math.inf, 5e-324]:
        assert deserialize_message(cdr.encode_float64(x), Float64).data == x
        assert cdr.decode_float64(serialize_message(Float64(data=x))) == x
    assert math.isnan(cdr.decode_float64(serialize_message(Float64(data=math.nan))))
    for _ in range(20):
        s = _stamp()
        c = deserialize_message(cdr.encode_clock(s), Clock).clock
        assert c.sec * 10 ** 9 + c.nanosec == s
        assert cdr.decode_clock(serialize_message(Clock(clock=Time(sec=s // 10 ** 9, nanosec=s % 10 ** 9)))) == s


def test_big_endian_is_read():
    be = b"\x00\x00\x00\x00" + struct.pack(">d", 2.5)
    assert cdr.decode_float64(be) == 2.5
    js = (b"\x00\x00\x00\x00" + struct.pack(">iI", 3, 4) + struct.pack(">I", 1) + b"\x00" + b"\x00" * 3
          + struct.pack(">I", 1) + struct.pack(">I", 2) + b"w\x00" + b"\x00" * 2
          + struct.pack(">I", 1) + struct.pack(">d", 1.25)   # the doubles start 8-aligned: no padding
          + struct.pack(">I", 0) + struct.pack(">I", 0))
    assert cdr.decode_joint_state(js) == (3_000_000_004, "", ["w"], (1.25,), (), ())


def test_bad_bytes_are_rejected_with_a_reason():
    # 124 bytes: names at 20..51, position count at 52 (doubles 60..75), velocity 76, effort count at 100
    good = cdr.JointStateEncoder(("wheel", "body_pitch"))(10, (1.0, 2.0), (3.0, 4.0), (5.0, 0.0))
    assert len(good) == 124
    cases = {
        "shorter than the encapsulation header": b"\x00\x01",
        "is not CDR_LE": b"\x00\x02\x00\x00" + good[4:],
        "message ends": good[:70],
        "cannot fit": good[:20] + struct.pack("<I", 10 ** 6) + good[24:],
        "is cut off": good[:36] + struct.pack("<I", 200) + good[40:],  # the length of "body_pitch"
    }
    for reason, data in cases.items():
        with pytest.raises(cdr.CdrError, match=reason):
            cdr.decode_joint_state(data)
    # like Fast CDR: a string without its NUL, or of length 0, is still read
    assert cdr.decode_joint_state(good[:33] + b"x" + good[34:])[2] == ["wheelx", "body_pitch"]
    zero_len_frame = cdr.CDR_LE + struct.pack("<iI", 1, 2) + struct.pack("<IIIII", 0, 0, 0, 0, 0)
    assert cdr.decode_joint_state(zero_len_frame) == (1_000_000_002, "", [], (), (), ())
    with pytest.raises(cdr.CdrError, match="longer than the message"):
        cdr.decode_joint_state(good[:100] + struct.pack("<I", 10 ** 6) + good[104:])  # effort's count
    with pytest.raises(cdr.CdrError, match="not UTF-8"):
        enc = cdr.JointStateEncoder(("\u00e4",))
        data = bytearray(enc(0, ()))
        data[data.index("\u00e4".encode())] = 0xFF
        cdr.decode_joint_state(bytes(data))
    with pytest.raises(cdr.CdrError, match="nanosec"):
        cdr.decode_clock(b"\x00\x01\x00\x00" + struct.pack("<iI", 0, 10 ** 9))
    with pytest.raises(cdr.CdrError, match="message ends"):
        cdr.decode_float64(b"\x00\x01\x00\x00\x00\x00")
    with pytest.raises(cdr.CdrError, match="int32 seconds"):
        cdr.encode_clock(2 ** 31 * 10 ** 9)


def test_repeated_layouts_decode_right():
    """The second message of a layout takes the template path: values, names and counts must still be its own."""
    a, b = cdr.JointStateEncoder(("ab", "cd")), cdr.JointStateEncoder(("xy", "zw"))
    shapes = [(2, 1, 0), (1, 2, 0), (0, 0, 3), (3, 0, 0)]  # same byte length, different sequences
    for k in range(200):
        enc, names = (a, ["ab", "cd"]) if k % 2 else (b, ["xy", "zw"])
        shape = shapes[k % len(shapes)]
        stamp, seqs = _stamp(), [tuple(_floats(n)) for n in shape]
        assert cdr.decode_joint_state(enc(stamp, *seqs)) == (stamp, "", names, *seqs)
        f, t = tuple(_floats(3)), tuple(_floats(3))
        frame = "ab" if k % 2 else "xy"
        assert cdr.decode_wrench_stamped(cdr.WrenchStampedEncoder(frame)(stamp, f, t)) == (stamp, frame, f, t)
    with pytest.raises(cdr.CdrError, match="nanosec"):  # a bad stamp in a known layout is still refused
        data = bytearray(a(0, (1.0,), (2.0,), ()))
        cdr.decode_joint_state(bytes(data))
        data[8:12] = struct.pack("<I", 10 ** 9)
        cdr.decode_joint_state(bytes(data))


@pytest.mark.parametrize("frame", ["", "a", "imu_link", "odom_frame"])
def test_imu_both_ways(frame):
    from sensor_msgs.msg import Imu
    enc = cdr.ImuEncoder(frame)
    for _ in range(20):
        stamp = _stamp()
        q, qc, w, wc, a, ac = (tuple(_floats(n)) for n in (4, 9, 3, 9, 3, 9))
        m = deserialize_message(enc(stamp, q, qc, w, wc, a, ac), Imu)   # ours -> rclpy
        assert m.header.stamp.sec * 10 ** 9 + m.header.stamp.nanosec == stamp and m.header.frame_id == frame
        o, av, la = m.orientation, m.angular_velocity, m.linear_acceleration
        assert (o.x, o.y, o.z, o.w) == q and (av.x, av.y, av.z) == w and (la.x, la.y, la.z) == a
        assert (tuple(m.orientation_covariance), tuple(m.angular_velocity_covariance),
                tuple(m.linear_acceleration_covariance)) == (qc, wc, ac)
        decoded = cdr.decode_imu(serialize_message(m))   # rclpy -> ours (the first parsed, the rest by template)
        assert decoded == (stamp, frame, q, qc, w, wc, a, ac) == cdr.decode_imu(enc(stamp, q, qc, w, wc, a, ac))


def test_bad_imu_bytes_are_rejected():
    good = cdr.ImuEncoder("imu_link")(10, (0.0,) * 4, (-1.0,) + (0.0,) * 8, (0.0, 1.0, 0.0), (0.0,) * 9,
                                      (0.0, 0.0, 9.81), (0.0,) * 9)
    for data, reason in ((good[:-8], "message ends"), (b"\x00\x01", "shorter than the encapsulation header"),
                         (b"\x00\x05" + good[2:], "is not CDR_LE"), (good[:12] + struct.pack("<I", 999) + good[16:],
                                                                      "is cut off")):
        with pytest.raises(cdr.CdrError, match=reason):
            cdr.decode_imu(data)
