"""The graph's per-period messages as CDR bytes, encoded and decoded without rclpy message objects.

rclpy turns every typed message into a Python object, converts it to a C struct and
(de)serializes it by introspection.  For the small messages the graph exchanges every
control period that costs more CPU than the control law itself (the repository's docs/benchmarks-history.md,
"What the profiles showed, and what was done": a typed Float64 ping-pong manages about 60 % of the round trips
of a serialized one).  So the nodes publish bytes (``Publisher.publish(bytes)``), subscribe with ``raw=True`` and use
this module.  The bytes are standard ROS 2 CDR (XCDR1; encapsulation CDR_LE, and
CDR_BE when decoding), so every ROS tool sees the usual types on the usual topics;
the tests check each function against rclpy's own serializer.

Layouts (alignment counts from the first byte after the 4-byte encapsulation header):

    builtin_interfaces/Time      int32 sec, uint32 nanosec
    std_msgs/Header              Time stamp, string frame_id
    sensor_msgs/JointState       Header, string[] name, float64[] position, float64[] velocity, float64[] effort
    geometry_msgs/WrenchStamped  Header, Vector3 force, Vector3 torque     (Vector3: float64 x, y, z)
    sensor_msgs/Imu              Header, Quaternion orientation (x, y, z, w), float64[9] orientation_covariance,
                                 Vector3 angular_velocity, float64[9] angular_velocity_covariance,
                                 Vector3 linear_acceleration, float64[9] linear_acceleration_covariance
    std_msgs/Float64             float64 data
    nav_msgs/Odometry            Header, string child_frame_id, Pose (Point xyz, Quaternion xyzw), float64[36],
                                 Twist (Vector3 linear, angular), float64[36]       (decoded only: the report)
    rosgraph_msgs/Clock          Time clock

Decoding raises :class:`CdrError` (a ``ValueError``) on anything that is not such a
message: short buffers, unknown encapsulation, strings cut off or not UTF-8, sequence
lengths past the end.  Bytes after the message are ignored, as other CDR readers
do (rclpy's ``serialize_message`` leaves a few).  Values are not judged (NaN is the
caller's business; :mod:`.layouts` judges them).  Nothing here imports ROS.  (Both directions
of the codec stay in this one module, a little over 300 lines: each layout beside its mirror.)
"""
from __future__ import annotations

import functools
import struct
from typing import Dict, List, Optional, Sequence, Tuple, cast

from .errors import CdrError
from .stamps import NS_PER_S as _NS, join_ns, split_ns

__all__ = ["CDR_LE", "CdrError", "JointStateEncoder", "WrenchStampedEncoder", "ImuEncoder", "IMU_DOUBLES",
           "decode_clock", "decode_float64", "decode_joint_state", "decode_wrench", "decode_wrench_stamped",
           "decode_imu", "decode_odometry", "decode_string", "peek_stamp", "encode_clock", "encode_float64",
           "encode_wrench", "encode_string", "split_ns"]

IMU_DOUBLES = 4 + 9 + 3 + 9 + 3 + 9   # sensor_msgs/Imu after its Header: every field a float64, no sequence

CDR_LE = b"\x00\x01\x00\x00"
_V3 = Tuple[float, float, float]   # a vector xyz (the typing of the decoders below)


# Compiled formats; bounded, since a foreign publisher can send any sequence length.
_st = functools.lru_cache(maxsize=256)(struct.Struct)


# --- decoding --------------------------------------------------------------------------------------

class _Reader:
    __slots__ = ("buf", "pos", "e", "end")

    def __init__(self, data, what: str):
        if len(data) < 4:
            raise CdrError(f"{what}: {len(data)} bytes, shorter than the encapsulation header")
        if data[0] != 0 or data[1] not in (0, 1):
            raise CdrError(f"{what}: encapsulation {bytes(data[:2]).hex()} is not CDR_LE (0001) or CDR_BE (0000)")
        self.buf = data
        self.pos = 4
        self.e = "<" if data[1] == 1 else ">"
        # The last two bits of the options say how many padding bytes end the payload (XCDR): they are
        # not part of the message, so a payload cut short and padded up is still found short.
        self.end = len(data) - (data[3] & 3)

    def _take(self, fmt: str, size: int, align: int):
        pos = self.pos + (-(self.pos - 4) % align)
        if pos + size > self.end:
            raise CdrError(f"message ends at byte {self.end}, needs {pos + size}")
        self.pos = pos + size
        return _st(self.e + fmt).unpack_from(self.buf, pos)

    def u32(self) -> int:
        return self._take("I", 4, 4)[0]

    def time_ns(self) -> int:
        sec, nsec = self._take("iI", 8, 4)
        if nsec >= _NS:
            raise CdrError(f"nanosec {nsec} >= 1e9")
        return join_ns(sec, nsec)

    def string(self) -> str:
        n = self.u32()
        end = self.pos + n
        if end > self.end:
            raise CdrError(f"string of length {n} at byte {self.pos} is cut off at byte {self.end}")
        # Length includes the NUL; like Fast CDR, also take a length of 0 or a missing NUL.
        stop = end - 1 if n and self.buf[end - 1] == 0 else end
        try:
            s = bytes(self.buf[self.pos:stop]).decode("utf-8")
        except UnicodeDecodeError as exc:
            raise CdrError(f"string at byte {self.pos} is not UTF-8: {exc}") from None
        self.pos = end
        return s

    def doubles(self, n: int) -> Tuple[float, ...]:
        return self._take(f"{n}d", 8 * n, 8) if n else ()

    def double_seq(self) -> Tuple[float, ...]:
        n = self.u32()
        if 8 * n > self.end:
            raise CdrError(f"sequence of {n} doubles is longer than the message")
        return self.doubles(n)


# Messages of one publisher share their layout (frame_id, names, sequence lengths); the first
# one of each length is parsed field by field and leaves a template, the rest are checked
# against it (the bytes before the numbers must be equal) and read with one struct.  The
# cache is bounded in entries and in bytes, and a layout with a long prefix (long names,
# whatever a foreign publisher sends) is never kept: it is parsed field by field each time.
_templates: Dict[Tuple[str, int, bytes], Tuple[int, bytes, struct.Struct, tuple, tuple]] = {}
_MAX_TEMPLATES = 64
_MAX_PREFIX = 1024                # bytes of frame_id and names a template may hold
_template_bytes = [0]             # bytes held by the cache now (prefixes, counted twice: bytes and strings)


def _fast(kind: str, data):
    if len(data) < 12:
        return None
    t = _templates.get((kind, len(data), bytes(data[:4])))
    if t is None:
        return None
    body_at, prefix, body, counts_at, result_prefix = t
    if data[12:body_at] != prefix:
        return None
    vals = body.unpack_from(data, body_at)
    for i, n in counts_at:
        if vals[i] != n:
            return None
    sec, nsec = _st(body.format[0] + "iI").unpack_from(data, 4)
    if nsec >= _NS:
        return None
    return join_ns(sec, nsec), result_prefix, vals


def _learn(kind: str, data, body_at: int, fmt: str, counts_at: tuple, result_prefix: tuple) -> None:
    size = body_at - 12
    if size > _MAX_PREFIX or len(fmt) > _MAX_PREFIX:
        return
    if len(_templates) >= _MAX_TEMPLATES or _template_bytes[0] + 2 * size > _MAX_TEMPLATES * _MAX_PREFIX:
        _templates.clear()
        _template_bytes[0] = 0
    _templates[(kind, len(data), bytes(data[:4]))] = (body_at, bytes(data[12:body_at]), _st(fmt), counts_at,
                                                      result_prefix)
    _template_bytes[0] += 2 * size


def decode_joint_state(data) -> Tuple[int, str, List[str], Tuple[float, ...], Tuple[float, ...], Tuple[float, ...]]:
    """sensor_msgs/JointState -> (stamp_ns, frame_id, name, position, velocity, effort)."""
    hit = _fast("JointState", data)
    if hit is not None:
        stamp, (frame, names), v = hit
        n1 = v[0]
        n2 = v[n1 + 1]
        return stamp, frame, list(names), v[1:n1 + 1], v[n1 + 2:n1 + 2 + n2], v[n1 + 3 + n2:]
    r = _Reader(data, "JointState")
    stamp = r.time_ns()
    frame = r.string()
    n = r.u32()
    if 4 * n > len(data):
        raise CdrError(f"JointState: {n} names cannot fit in {len(data)} bytes")
    names = [r.string() for _ in range(n)]
    body_at = r.pos
    fmt, counts_at, at = r.e, [], r.pos
    seqs: List[Tuple[float, ...]] = []
    for _ in range(3):
        pad = -(at - 4) % 4
        fmt += f"{pad}xI"
        at += pad
        seq = r.double_seq()
        counts_at.append((sum(1 + len(x) for x in seqs), len(seq)))
        at += 4
        if seq:
            pad = -(at - 4) % 8
            fmt += f"{pad}x{len(seq)}d"
            at += pad + 8 * len(seq)
        seqs.append(seq)
    _learn("JointState", data, body_at, fmt, tuple(counts_at), (frame, tuple(names)))
    return stamp, frame, names, seqs[0], seqs[1], seqs[2]


def decode_wrench_stamped(data) -> Tuple[int, str, Tuple[float, float, float], Tuple[float, float, float]]:
    """geometry_msgs/WrenchStamped -> (stamp_ns, frame_id, force xyz, torque xyz)."""
    hit = _fast("WrenchStamped", data)
    if hit is not None:
        stamp, (frame,), v = hit
        return stamp, frame, v[:3], v[3:]
    r = _Reader(data, "WrenchStamped")
    stamp = r.time_ns()
    frame = r.string()
    body_at = r.pos
    v = r.doubles(6)
    _learn("WrenchStamped", data, body_at, f"{r.e}{-(body_at - 4) % 8}x6d", (), (frame,))
    return stamp, frame, cast(_V3, v[:3]), cast(_V3, v[3:])


def decode_imu(data) -> Tuple[int, str, Tuple[float, ...], Tuple[float, ...], Tuple[float, ...], Tuple[float, ...],
                               Tuple[float, ...], Tuple[float, ...]]:
    """sensor_msgs/Imu -> (stamp_ns, frame_id, orientation xyzw, orientation_covariance (9), angular_velocity xyz,
    angular_velocity_covariance (9), linear_acceleration xyz, linear_acceleration_covariance (9))."""
    hit = _fast("Imu", data)
    if hit is not None:
        stamp, (frame,), v = hit
    else:
        r = _Reader(data, "Imu")
        stamp = r.time_ns()
        frame = r.string()
        body_at = r.pos
        v = r.doubles(IMU_DOUBLES)
        _learn("Imu", data, body_at, f"{r.e}{-(body_at - 4) % 8}x{IMU_DOUBLES}d", (), (frame,))
    return stamp, frame, v[0:4], v[4:13], v[13:16], v[16:25], v[25:28], v[28:37]


def decode_odometry(data) -> Tuple[int, str, str, Tuple[float, ...]]:
    """nav_msgs/Odometry -> (stamp_ns, frame_id, child_frame_id, pose: position xyz and orientation xyzw)."""
    r = _Reader(data, "Odometry")
    stamp = r.time_ns()
    frame = r.string()
    child = r.string()
    return stamp, frame, child, r.doubles(7)


def decode_wrench(data) -> Tuple[Tuple[float, float, float], Tuple[float, float, float]]:
    """geometry_msgs/Wrench -> (force xyz, torque xyz)."""
    v = _Reader(data, "Wrench").doubles(6)
    return cast(_V3, v[:3]), cast(_V3, v[3:])


def peek_stamp(data):
    """The leading ``Time`` of a stamped message (a Header's stamp, a Clock's clock) in ns, or None."""
    if len(data) < 12 or data[0] != 0 or data[1] not in (0, 1):
        return None
    sec, nsec = _st("<iI" if data[1] == 1 else ">iI").unpack_from(data, 4)
    return join_ns(sec, nsec) if nsec < _NS else None


def decode_float64(data) -> float:
    """std_msgs/Float64 -> data."""
    r = _Reader(data, "Float64")
    x = r.doubles(1)[0]
    return x


def decode_clock(data) -> int:
    """rosgraph_msgs/Clock -> clock in ns."""
    r = _Reader(data, "Clock")
    t = r.time_ns()
    return t

def decode_string(data) -> str:
    """std_msgs/String -> its text."""
    return _Reader(data, "String").string()


def encode_string(text: str) -> bytes:
    """std_msgs/String of ``text`` (CDR_LE)."""
    b = text.encode("utf-8") + b"\0"
    return CDR_LE + struct.pack("<I", len(b)) + b


def decode_pose_stamped(data) -> Tuple[int, str, Tuple[float, float, float], Tuple[float, float, float, float]]:
    """geometry_msgs/PoseStamped -> (stamp_ns, frame_id, position xyz, orientation xyzw)."""
    r = _Reader(data, "PoseStamped")
    stamp = r.time_ns()
    frame = r.string()
    v = r.doubles(7)
    return stamp, frame, cast(_V3, v[:3]), cast(Tuple[float, float, float, float], v[3:])


# --- encoding (little endian) ----------------------------------------------------------------------

def _string(s: str, pos: int) -> Tuple[bytes, int]:
    """(padding + length + bytes + NUL, new position) for a string starting at payload offset ``pos``."""
    b = s.encode("utf-8") + b"\x00"
    pad = -pos % 4
    return b"\x00" * pad + struct.pack("<I", len(b)) + b, pos + pad + 4 + len(b)


def _header_tail(frame_id: str, names: Optional[Sequence[str]] = None) -> Tuple[bytes, int]:
    """The bytes after the stamp: frame_id and, for a JointState, the name sequence; and the end offset."""
    out, pos = _string(frame_id, 8)
    if names is not None:
        pad = -pos % 4
        out += b"\x00" * pad + struct.pack("<I", len(names))
        pos += pad + 4
        for name in names:
            b, pos = _string(name, pos)
            out += b
    return out, pos


class JointStateEncoder:
    """Encode JointStates with a fixed ``frame_id`` and ``name`` list (the prefix is built once).

    >>> enc = JointStateEncoder(("wheel", "body_pitch"))
    >>> data = enc(5_000_000, (0.0, -0.17), (0.0, 0.0), (0.0, 0.0))
    """

    def __init__(self, names: Sequence[str], frame_id: str = ""):
        self.names = list(names)
        self._tail, self._pos = _header_tail(frame_id, self.names)
        self._stamp = _st("<iI")
        self._cache: Dict[Tuple[int, int, int], struct.Struct] = {}

    def _layout(self, n_pos: int, n_vel: int, n_eff: int) -> struct.Struct:
        """One struct for the three sequences: count (align 4), doubles (align 8), for each."""
        fmt, pos = "<", self._pos
        for n in (n_pos, n_vel, n_eff):
            pad = -pos % 4
            fmt += f"{pad}xI"
            pos += pad + 4
            if n:
                pad = -pos % 8
                fmt += f"{pad}x{n}d"
                pos += pad + 8 * n
        return struct.Struct(fmt)

    def __call__(self, stamp_ns: int, position: Sequence[float], velocity: Sequence[float] = (),
                 effort: Sequence[float] = ()) -> bytes:
        key = (len(position), len(velocity), len(effort))
        st = self._cache.get(key)
        if st is None:
            st = self._cache[key] = self._layout(*key)
        return (CDR_LE + self._stamp.pack(*split_ns(stamp_ns)) + self._tail
                + st.pack(key[0], *position, key[1], *velocity, key[2], *effort))


class WrenchStampedEncoder:
    """Encode WrenchStampeds with a fixed ``frame_id``."""

    def __init__(self, frame_id: str = ""):
        self._tail, pos = _header_tail(frame_id)
        self._body = struct.Struct(f"<{-pos % 8}x6d")
        self._stamp = _st("<iI")

    def __call__(self, stamp_ns: int, force: Sequence[float], torque: Sequence[float]) -> bytes:
        return CDR_LE + self._stamp.pack(*split_ns(stamp_ns)) + self._tail + self._body.pack(*force, *torque)


class PoseStampedEncoder:
    """Encode geometry_msgs/PoseStamped messages with a fixed ``frame_id``: position xyz, orientation xyzw."""

    def __init__(self, frame_id: str = ""):
        self._tail, pos = _header_tail(frame_id)
        self._body = struct.Struct(f"<{-pos % 8}x7d")
        self._stamp = _st("<iI")

    def __call__(self, stamp_ns: int, position: Sequence[float], orientation: Sequence[float]) -> bytes:
        return CDR_LE + self._stamp.pack(*split_ns(stamp_ns)) + self._tail + self._body.pack(*position, *orientation)


class ImuEncoder:
    """Encode sensor_msgs/Imu messages with a fixed ``frame_id``."""

    def __init__(self, frame_id: str = ""):
        self._tail, pos = _header_tail(frame_id)
        self._body = struct.Struct(f"<{-pos % 8}x{IMU_DOUBLES}d")
        self._stamp = _st("<iI")

    def __call__(self, stamp_ns: int, orientation: Sequence[float], orientation_cov: Sequence[float],
                 angular_velocity: Sequence[float], angular_velocity_cov: Sequence[float],
                 linear_acceleration: Sequence[float], linear_acceleration_cov: Sequence[float]) -> bytes:
        return (CDR_LE + self._stamp.pack(*split_ns(stamp_ns)) + self._tail
                + self._body.pack(*orientation, *orientation_cov, *angular_velocity, *angular_velocity_cov,
                                  *linear_acceleration, *linear_acceleration_cov))


_F64 = struct.Struct("<4sd")
_WRENCH6 = struct.Struct("<4s6d")
_CLOCK = struct.Struct("<4siI")


def encode_float64(x: float) -> bytes:
    return _F64.pack(CDR_LE, x)


def encode_wrench(force: Sequence[float], torque: Sequence[float]) -> bytes:
    """geometry_msgs/Wrench (no header)."""
    return _WRENCH6.pack(CDR_LE, *force, *torque)


def encode_clock(stamp_ns: int) -> bytes:
    return _CLOCK.pack(CDR_LE, *split_ns(stamp_ns))
