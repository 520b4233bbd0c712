"""The trajectory table: one row per control period, built the same way by every source.

Row k holds the state at t_k, the command u_k computed from it (the torque applied over
[t_k, t_{k+1})), the estimate tau_hat_k and the true lumped disturbance tau_d at t_k, and,
where the source has them, the controller's internal signals.  The offline simulator, the
``plant_sim`` node and the report (from a bag) all append rows with
:meth:`TrajectoryTable.append`; a source that does not know a value (the plant does not
see the observer's estimates) writes NaN, and :func:`join_estimates` fills the estimates in
later by stamp.
"""
from __future__ import annotations

import math
from array import array
from dataclasses import dataclass, field, replace
from typing import Any, Dict, Iterable, Sequence, Tuple

import numpy as np

__all__ = ["TRAJECTORY_COLUMNS", "INTERNAL_COLUMNS", "COLUMNS", "RAW_COLUMNS", "ESTIMATE_COLUMNS", "DRIVE_COLUMNS",
           "EXCITATION_COLUMNS", "MOTION_COLUMNS", "YAW_COLUMNS", "POSE_COLUMNS",
           "ALL_COLUMNS", "FAILURES", "FALL", "BAD_COMMAND",
           "DIVERGED", "FAILURE_COLUMNS", "Trajectory", "TrajectoryTable",
           "join_estimates", "stamp_key"]

# The trajectory every source has (simulator, plant_sim's CSV, a bag), then the controller's internals.
TRAJECTORY_COLUMNS = ["t", "theta_w", "theta_b", "dtheta_w", "dtheta_b", "u", "tau_hat1", "tau_hat2",
                      "tau_d1", "tau_d2"]
INTERNAL_COLUMNS = ["u_dsc", "u_taud", "S1", "S2", "x4_bar", "x4d"]
COLUMNS = TRAJECTORY_COLUMNS + INTERNAL_COLUMNS
# with raw sensors (docs/theory.md 6.4): the sample of the period and the state the estimator made of it
RAW_COLUMNS = ["gyro", "accel_x", "accel_z", "encoder", "encoder_rate"]
ESTIMATE_COLUMNS = ["theta_w_hat", "theta_b_hat", "dtheta_w_hat", "dtheta_b_hat"]
# with the motor model (theory.md 6.7): the torque that acted over [t_k, t_k+1) beside the command u, and the drive's
# worst saturation code of the period (core.plants.drive: 0 none, 1 current, 2 voltage); NaN in a row no period followed
DRIVE_COLUMNS = ["u_applied", "drive_saturation"]
EXCITATION_COLUMNS = ["excitation"]   # the controller's excitation, included in u (identification)
MOTION_COLUMNS = ["v_ref", "theta_w_ref"]   # the period's motion references (theory 6.11: v* [m/s], theta_w* [rad])
# the yaw stage's reference psi'* [rad/s], yaw torque u_psi [N m] and the gyro's yaw rate it read [rad/s] (theory 6.13)
YAW_COLUMNS = ["dpsi_ref", "u_psi", "gyro_z"]
# a spatial plant's 3D pose at t_k (core.plants.plant.Pose, backend mujoco: docs/theory.md 6.10), after every other
# column
POSE_COLUMNS = ["x", "y", "yaw", "roll", "wheel_left", "wheel_right"]
ALL_COLUMNS = (COLUMNS + RAW_COLUMNS + ESTIMATE_COLUMNS + DRIVE_COLUMNS + EXCITATION_COLUMNS + MOTION_COLUMNS
               + YAW_COLUMNS + POSE_COLUMNS)
_NAN_POSE = (math.nan,) * len(POSE_COLUMNS)
_NAN2 = (math.nan, math.nan)

# why a run failed (a Trajectory's ``record['failure']``; a batch's ``failure`` codes are the index here, 0: it did
# not): the robot fell (|theta_b| beyond the fall angle), the law's command was refused (not a finite number, or
# implausible: the driver's ``bad_command``), or the state diverged (not a finite number after a period)
FAILURES = ("", "fall", "bad_command", "diverged")
FALL, BAD_COMMAND, DIVERGED = 1, 2, 3
FAILURE_COLUMNS = ("t_fall", "failure")   # a failed run's CSV (mwip_sim --csv): when, and why (a FAILURES index)


def stamp_key(t: float) -> int:
    """The integer nanosecond stamp of a time in seconds: the key estimates join on."""
    return int(round(t * 1e9))


@dataclass
class Trajectory:
    """A finished run: ``columns`` maps a column name to its array (one entry per period).

    ``record`` holds what the run's source says of it beside the table (a bag's plant log: the fall,
    the configured duration, the torque limit; see :func:`mwip_ros.runs.read_bag_run`; a failed offline run:
    ``t_fall``, ``fall_text`` and ``failure``, a :data:`FAILURES` name), empty when it says nothing."""

    label: str
    columns: Dict[str, np.ndarray]
    fallen: bool
    h: float
    record: Dict[str, Any] = field(default_factory=dict)

    @property
    def t(self) -> np.ndarray:
        return self.columns["t"]

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]

    def __len__(self) -> int:
        return len(self.columns["t"])


class TrajectoryTable:
    """Rows appended period by period into one flat array of doubles.

    No Python object per row: a node that runs for hours keeps 80 bytes per period and
    gives the garbage collector nothing to scan (BENCHMARKS.md, "Measurements moved out of
    the core's docstrings").  ``internals=True`` adds :data:`INTERNAL_COLUMNS`.

    Bounded for a run of days: the table keeps the rows up to ``t <= keep_until`` and the newest one; each row is
    handed to ``sink(k, row)`` once final (when the next is appended, or at :meth:`flush`: :meth:`set_drive` may
    still change the newest), so a writer streams the whole run to disk (:class:`mwip_ros.runs.CsvStream`).  The
    periods with the drive saturated are counted over every row (:attr:`saturated`).
    """

    def __init__(self, internals: bool = False, raw: bool = False, drive: bool = False, excitation: bool = False,
                 keep_until: float = math.inf, sink=None, motion: bool = False, pose: bool = False,
                 yaw: bool = False):
        self.internals = internals
        self.yaw = yaw
        self.excitation = excitation
        self.motion = motion
        self.pose = pose
        self.names = ((COLUMNS if internals else TRAJECTORY_COLUMNS) + ((RAW_COLUMNS + ESTIMATE_COLUMNS) if raw
                                                                         else []) + (DRIVE_COLUMNS if drive else [])
                      + (EXCITATION_COLUMNS if excitation else []) + (MOTION_COLUMNS if motion else [])
                      + (YAW_COLUMNS if yaw else []) + (POSE_COLUMNS if pose else []))
        self.width = len(self.names)
        self.n_extra = len(RAW_COLUMNS + ESTIMATE_COLUMNS) if raw else 0
        self.drive = drive
        self.rows = array("d")      # the kept rows, then the newest row
        self.keep_until = keep_until
        self.sink = sink
        self.count = 0              # rows appended
        self.saturated = 0          # final rows whose drive_saturation > 0
        self._final = 0             # rows handed to the sink
        self._newest_kept = True

    def _finish_newest(self) -> None:
        if self._final < self.count:
            row = self.rows[len(self.rows) - self.width:]
            if self.sink is not None:
                self.sink(self.count - 1, row)
            if self.drive and row[self.names.index("drive_saturation")] > 0:
                self.saturated += 1
            self._final = self.count

    def flush(self) -> None:
        """The newest row is final: hand it to the sink (the end of a run)."""
        self._finish_newest()

    @property
    def dropped(self) -> int:
        """Rows no longer in memory (past ``keep_until``, and not the newest)."""
        return self.count - len(self.rows) // self.width

    def append(self, t: float, x, u: float, tau_hat: Sequence[float] = _NAN2, tau_d: Sequence[float] = _NAN2,
               out=None, extra: Sequence[float] = (), pose=None) -> None:
        """Row of state ``x`` at ``t`` with command ``u``; ``out`` is the law's internals (a dict of its signals,
        :meth:`mwip_ros.core.laws.Law.step`, or an object with them as attributes); one it lacks is NaN.
        ``extra``: with ``raw``, the raw sample and the estimate (:data:`RAW_COLUMNS`, :data:`ESTIMATE_COLUMNS`;
        empty: NaN).  ``pose``: with ``pose``, the plant's :class:`~.plant.Pose` at t_k (None: NaN)."""
        self._finish_newest()
        if not self._newest_kept:
            del self.rows[len(self.rows) - self.width:]
        self._newest_kept = t <= self.keep_until
        self.count += 1
        self.rows.extend((t, x[0], x[1], x[2], x[3], u, tau_hat[0], tau_hat[1], tau_d[0], tau_d[1]))
        if self.internals:
            if isinstance(out, dict):
                self.rows.extend([out.get(c, math.nan) for c in INTERNAL_COLUMNS])
            else:
                self.rows.extend([getattr(out, c, math.nan) for c in INTERNAL_COLUMNS])
        if self.n_extra:
            self.rows.extend(extra if len(extra) == self.n_extra else (math.nan,) * self.n_extra)
        if self.drive:
            self.rows.extend(_NAN2)   # u_applied, drive_saturation: known once the period is integrated
        if self.excitation:
            self.rows.append(out.get("excitation", math.nan) if isinstance(out, dict) else math.nan)
        if self.motion:
            self.rows.extend([out.get(c, math.nan) if isinstance(out, dict) else math.nan for c in MOTION_COLUMNS])
        if self.yaw:
            self.rows.extend([out.get(c, math.nan) if isinstance(out, dict) else math.nan for c in YAW_COLUMNS])
        if self.pose:
            self.rows.extend(_NAN_POSE if pose is None else (pose.x, pose.y, pose.yaw, pose.roll, pose.wheel_left,
                                                              pose.wheel_right))

    def set_drive(self, u_applied: float, saturation: int) -> None:
        """The last row's :data:`DRIVE_COLUMNS`, once its period has been integrated."""
        if self.drive:
            at = len(self.rows) - self.width + self.names.index("u_applied")
            self.rows[at] = u_applied
            self.rows[at + 1] = float(saturation)

    def __len__(self) -> int:
        return self.count

    def last(self, name: str) -> float:
        return self.rows[len(self.rows) - self.width + self.names.index(name)]

    def trajectory(self, label: str, fallen: bool, h: float) -> Trajectory:
        """The rows in memory (every row, unless some were past ``keep_until``: then those up to it and the
        newest)."""
        table = np.array(self.rows, dtype=float).reshape(len(self.rows) // self.width, self.width)
        return Trajectory(label, {c: table[:, i] for i, c in enumerate(self.names)}, fallen, h)


def join_estimates(traj: Trajectory, estimates: Iterable[Tuple[float, float, float]]) -> Trajectory:
    """A copy of ``traj`` whose tau_hat columns hold the estimates ``(t, tau_hat1, tau_hat2)`` of the same
    stamp (rows without one keep what they had).  A row's stamp is its ``stamp`` column where it has one (a
    realtime plant stamps with its clock), else its ``t``."""
    by_stamp = {stamp_key(t): (a, b) for t, a, b in estimates}
    cols = dict(traj.columns)
    th1, th2 = cols["tau_hat1"].copy(), cols["tau_hat2"].copy()
    for i, t in enumerate(cols.get("stamp", cols["t"])):
        e = by_stamp.get(stamp_key(t))
        if e is not None:
            th1[i], th2[i] = e
    cols["tau_hat1"], cols["tau_hat2"] = th1, th2
    return replace(traj, columns=cols)
