"""The raw columns of ``mwip_identify --raw`` from a bag: what a robot records of itself (docs/real-robot.md).

A robot's bag of the realtime graph with raw sensors holds ``imu/data_raw`` (sensor_msgs/Imu: the pitch rate and the
specific force) and ``wheel_encoder`` (sensor_msgs/JointState: the wheel's angle relative to the body, its rate and
the torque that acted over the previous period), both stamped ``t_k``; nothing else is read (neither the state
estimate nor a simulator's truth).  The messages are read by the bag layer (:func:`mwip_ros.bag.check`,
:func:`mwip_ros.bag.raw_messages`, :class:`mwip_ros.bag.segments.Segments` for a bag of several runs) and decoded by
the message layer (:func:`mwip_ros.msgs.layouts.parse_imu`, :func:`~mwip_ros.msgs.layouts.parse_encoder`), as
:func:`mwip_ros.runs.read_bag_run` reads them.

Row k is a stamp with both samples: ``t`` (seconds from the first row, on the stamps' nanosecond grid:
:func:`on_stamp_grid`, the same for a CSV), ``gyro``, ``accel_x``, ``accel_z``, ``encoder``, ``encoder_rate``, and
``u_applied``: the torque that acted over [t_k, t_k+1), which the encoder reports with sample k+1.  Where sample k+1 is
not one period after sample k (a lost message), that torque is unknown: NaN, and ``identify_raw`` leaves the
periods without a torque out of its windows.  A sample recorded twice (same stamp, same values) counts once; two
different samples of one stamp are refused.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Dict, Optional

import numpy as np

__all__ = ["RAW_COLUMNS", "RawLog", "read_raw_bag", "on_stamp_grid", "saturated_share"]

RAW_COLUMNS = ("t", "gyro", "accel_x", "accel_z", "encoder", "encoder_rate", "u_applied")


@dataclass
class RawLog:
    """The raw columns (:data:`RAW_COLUMNS`) and what the reader found: samples recorded twice (counted once),
    stamps with only one of the two sensors (left out), periods whose torque no sample reports (NaN)."""

    columns: Dict[str, np.ndarray]
    duplicates: int = 0
    unpaired: int = 0
    missing_torque: int = 0


def on_stamp_grid(t) -> np.ndarray:
    """``t`` [s] as seconds from its first value on the nanosecond grid of ROS stamps: ``round((t - t0) 1e9) / 1e9``.
    A bag's stamps are integer nanoseconds and a CSV's ``t`` is ``k h`` in floating point; both give the same floats
    here, so a bag and the CSV of the same run are fitted to the bit."""
    t = np.asarray(t, dtype=float)
    if not len(t):
        return t
    return np.round((t - t[0]) * 1e9) / 1e9


def saturated_share(u) -> tuple:
    """(periods, pinned, limit) of a torque column: the periods with a finite torque, how many of them sit at the
    largest magnitude the log reaches (to 1e-9 of it: a drive on its torque or current limit holds exactly that), and
    that magnitude [N m]."""
    u = np.asarray(u, dtype=float)
    u = np.abs(u[np.isfinite(u)])
    if not len(u):
        return 0, 0, math.nan
    top = float(u.max())
    return len(u), int(np.count_nonzero(u >= top * (1 - 1e-9))) if top > 0 else 0, top


class _Samples:
    """Samples of one sensor by stamp: a repeat with the same values counts once, one with other values is refused."""

    def __init__(self, bag, topic: str, width: int):
        from mwip_ros.runs import _Stamped
        self.bag, self.topic = bag, topic
        self.rows = _Stamped(width, topic)
        self.duplicates = 0

    def put(self, stamp: int, values) -> None:
        old = self.rows.get(stamp)
        if old is None:
            self.rows.put(self.bag, stamp, values)
        elif old == tuple(float(v) for v in values):
            self.duplicates += 1
        else:
            raise ValueError(f"{self.bag}: two different {self.topic} samples with the stamp {stamp} ns: a log with "
                             f"two records of one period cannot be identified")


def read_raw_bag(bag, segment: Optional[int] = None) -> RawLog:
    """The raw columns of ``bag`` (module doc); ``segment``: the run of a bag of several (0-based), as
    :func:`mwip_ros.runs.read_bag_run`.  ValueError (one line) for a bag that cannot be read (cut short: a recording
    without its summary, a damaged chunk), of several runs without ``segment``, or without the raw sensors."""
    from mwip_ros.bag import check, raw_messages
    from mwip_ros.bag.segments import Segments, SpliceError
    from mwip_ros.msgs import BadMessage
    from mwip_ros.msgs import layouts as L
    from mwip_ros.msgs.topics import leaf
    from mwip_ros.runs import MAX_BAG_BYTES, check_size

    try:
        check_size(bag, MAX_BAG_BYTES, "bag")   # before a byte of it is read
    except ValueError as exc:
        raise ValueError(f"{bag}: {exc}") from None
    check(bag)   # a damaged chunk, a file cut short: BagError (a ValueError) naming it
    segs = Segments.from_bag(bag)   # the runs: the stamps of joint_states go back at a reset
    messages = raw_messages(bag)
    if segs.spliced:
        if segment is None:
            raise SpliceError(segs.refusal("an identification of one run").replace("(segment=", "(--run ")
                              .replace("segment=N", "--run N"))
        messages = segs.select(segment)
    imu, enc = _Samples(bag, "imu/data_raw", 3), _Samples(bag, "wheel_encoder", 3)
    for _log_time, topic, data in messages:
        name = leaf(topic)
        try:
            if name == "data_raw" and topic.endswith("imu/data_raw"):
                stamp, g, fx, fz = L.parse_imu(data)
                imu.put(stamp, (g, fx, fz))
            elif name == "wheel_encoder":
                stamp, phi, rate, torque = L.parse_encoder(data)
                enc.put(stamp, (phi, rate, torque))
        except BadMessage:
            continue   # not the robot's sample (a foreign publisher): not part of the run
    if not len(imu.rows) or not len(enc.rows):
        missing = " and ".join(t for t, s in (("imu/data_raw", imu), ("wheel_encoder", enc)) if not len(s.rows))
        raise ValueError(f"{bag}: no {missing} messages: --raw is for a bag of the raw sensors "
                         f"(sensors.model: raw, or a robot's IMU and encoder)")
    both = sorted(set(imu.rows.index) & set(enc.rows.index))
    unpaired = len(imu.rows) + len(enc.rows) - 2 * len(both)
    if len(both) < 2:
        raise ValueError(f"{bag}: {len(both)} stamp(s) with both an imu/data_raw and a wheel_encoder sample")
    stamps = np.array(both, dtype=np.int64)
    period = int(np.median(np.diff(stamps)))
    values = np.array([imu.rows.get(s) + enc.rows.get(s) for s in both], dtype=float)
    u = np.full(len(both), math.nan)
    nxt = np.diff(stamps) == period   # sample k+1 reports the torque of period k only when it is the next period
    u[:-1][nxt] = values[1:, 5][nxt]
    cols = {"t": (stamps - stamps[0]) / 1e9,   # as on_stamp_grid makes a CSV's t
            "gyro": values[:, 0], "accel_x": values[:, 1], "accel_z": values[:, 2], "encoder": values[:, 3],
            "encoder_rate": values[:, 4], "u_applied": u}
    return RawLog(cols, imu.duplicates + enc.duplicates, unpaired, int(np.count_nonzero(~nxt)))

