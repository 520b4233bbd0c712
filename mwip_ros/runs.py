"""Runs on disk: a trajectory's CSV, and a recorded bag rebuilt into the same trajectory table.

* :func:`write_csv` / :func:`read_csv`: the columns of :mod:`mwip_ros.core.closed_loop.trajectory`
  (whichever a run has, in that order), floats written exactly.  ``mwip_sim`` and
  ``plant_sim`` write whole trajectories; the ``disturbance_observer`` node writes
  ``t, tau_hat1, tau_hat2``, which :func:`load_run` joins to a plant CSV by stamp.
* :func:`read_bag_run`: states, applied torque, estimates and the true disturbance of a
  bag, matched by stamp and decoded by the message layer (:mod:`mwip_ros.msgs.layouts`);
  what the plant logged of the run (``/rosout``, ``/parameter_events``: its fall, its
  configured duration and torque limit) goes into the trajectory's ``record``
  (:func:`plant_record`).
"""
from __future__ import annotations

import csv
import math
import re
import warnings
from pathlib import Path
from typing import Dict, List, Optional

import numpy as np

from mwip_ros.core.plants.plant import Pose
from mwip_ros.core.closed_loop.trajectory import (ALL_COLUMNS, FAILURE_COLUMNS, FAILURES, TRAJECTORY_COLUMNS,
                                                 Trajectory, TrajectoryTable, join_estimates)
from mwip_ros.msgs import BadMessage
from mwip_ros.msgs import layouts as L
from mwip_ros.msgs.topics import leaf

__all__ = ["CsvStream", "write_csv", "read_csv", "read_bag_run", "read_bag_runs", "load_run", "load_runs",
           "plant_record", "PLANT_NODE", "ROBOT_SIDE_NODES", "MAX_ROWS", "MAX_CSV_BYTES", "MAX_BAG_BYTES", "check_size",
           "check_times", "RUN_COLUMNS"]

PLANT_NODE = "plant_sim"
# the nodes that own the robot's clock: plant_sim, or wheel_driver on a robot's side (docs/hardware.md); their logs
# and parameters are the run's record
ROBOT_SIDE_NODES = (PLANT_NODE, "wheel_driver")
# what they log (mwip_ros.nodes.loop.plant_sim, .wheel_driver): the start (the configured duration), a fall, an
# interruption
_FALLEN = re.compile(r"FALLEN at t = ([-+0-9.eE]+) s(?:: \|theta_b\| = [-+0-9.eE]+ > fall_angle ([-+0-9.eE]+))?")
_START = re.compile(r"(?:lockstep|realtime) (?:plant|driver): h = .*?, (?:([-+0-9.eE]+) s|until stopped), "
                    r"(?:seed|read_only)")
_INTERRUPTED = re.compile(r"interrupted at t = ([-+0-9.eE]+) s of ([-+0-9.eE]+) s")

NAN = math.nan
# What a run read from disk may hold: bounded before anything is allocated, refused above in one line.
MAX_ROWS = 2_000_000           # rows (samples): 2.8 h at 200 Hz; ~16 columns of float64 = 256 MB
MAX_CSV_BYTES = 1 << 30        # a CSV of MAX_ROWS full rows (16 repr floats, ~330 B a row) is ~660 MB
MAX_BAG_BYTES = 2 << 30        # a bag of MAX_ROWS periods (state, command, estimate, truth: ~600 B) is ~1.2 GB
MAX_CSV_COLUMNS = 64           # a trajectory has 37 at most (ALL_COLUMNS and stamp)
MAX_T = 1e10   # [s] |t| beyond this is no run; a realtime observer's CSV holds wall-clock stamps (1.8e9 s in 2026)
_HEADER_MAX = 1 << 16          # characters of a header line
MAX_LOG_MESSAGES = 100_000     # /rosout, /parameter_events messages of a bag kept for plant_record
# a run's CSV must have these (the estimates and the disturbance may be missing: NaN, as a plant CSV has)
RUN_COLUMNS = ("t", "theta_w", "theta_b", "dtheta_w", "dtheta_b", "u")


class CsvStream:
    """A trajectory CSV written row by row as a run goes (a node's ``csv``): the header ``names`` (in the
    trajectory table's order, then ``stamp``), then each row's floats written exactly (repr); the text of
    :func:`write_csv` for the same rows, without holding them.  :meth:`restart` empties the file (a plant's
    reset: the csv keeps the run from there)."""

    def __init__(self, path, names):
        self.names = list(names)
        self._f = open(path, "w", newline="")
        self._w = csv.writer(self._f, lineterminator="\n")
        self._w.writerow(self.names)

    def row(self, values) -> None:
        self._w.writerow([repr(float(x)) for x in values])

    def restart(self) -> None:
        self._f.seek(0)
        self._f.truncate()
        self._w.writerow(self.names)

    def close(self) -> None:
        self._f.close()

    def __enter__(self) -> "CsvStream":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def write_csv(run: Trajectory, path) -> None:
    """The columns ``run`` has, in the trajectory table's order (then ``stamp``, a realtime plant's message
    stamps in seconds when they are not ``t``), floats written exactly (repr)."""
    names = [c for c in (*ALL_COLUMNS, "stamp") if c in run.columns]
    cols = [run.columns[c] for c in names]
    rec = run.record or {}
    if run.fallen and rec.get("failure") in FAILURES[1:] and rec.get("t_fall") is not None:
        # a failed run (core.closed_loop.sim.simulate): when and why, in every row (read_csv gives them back as its
        # record)
        names += list(FAILURE_COLUMNS)
        cols += [np.full(len(run), float(rec["t_fall"])), np.full(len(run), float(FAILURES.index(rec["failure"])))]
    with CsvStream(path, names) as out:
        for row in zip(*cols):
            out.row(row)


def _mib(n: float) -> str:
    return f"{n / 2**20:,.0f} MiB" if n >= 2**20 else f"{n:,.0f} bytes"


def _limit_text() -> str:
    return f"{MAX_ROWS / 200 / 3600:.1f} h at 200 Hz"


def check_size(path, limit: int, what: str) -> int:
    """The size of ``path`` in bytes (a bag directory: its MCAP files'), checked before anything is read:
    ValueError, one line, above ``limit`` or for a file that is not a regular one (a FIFO, a device)."""
    from mwip_ros.yamlio import NotRegularFile, regular_size
    p = Path(path)
    try:   # a FIFO or a device is refused unread
        if p.is_dir():
            from mwip_ros.bag import mcap_files
            size = sum(regular_size(f, "MCAP file") for f in mcap_files(p))
        else:
            size = regular_size(p, what)
    except NotRegularFile as exc:
        raise ValueError(str(exc)) from None
    if size > limit:
        raise ValueError(f"{_mib(size)}, more than a {what} of a run of at most {MAX_ROWS:,} rows "
                         f"({_limit_text()}) takes ({_mib(limit)}); not read")
    return size


def read_csv(path, label: Optional[str] = None, max_rows: Optional[int] = None, ordered: bool = True,
             empty_ok: bool = False) -> Trajectory:
    """Read a CSV written by :func:`write_csv` (``mwip_sim --csv``, ``plant_sim``'s or the observer's ``csv``).

    Bounded whatever the file holds: the file's size is checked first (:data:`MAX_CSV_BYTES`), at most
    ``max_rows`` (default :data:`MAX_ROWS`) rows are read, at most :data:`MAX_CSV_COLUMNS` columns; ValueError
    (one line naming the file) for more, for a header without ``t``, a repeated column, a row that does not
    parse or has another number of fields, no rows, or a ``t`` that is not finite or (``ordered``: a run's
    table) decreases; an observer's CSV may go back in t (a plant reset re-initialises the observer) and
    (``empty_ok``) have no rows."""
    max_rows = MAX_ROWS if max_rows is None else max_rows
    try:
        size = check_size(path, MAX_CSV_BYTES, "CSV")
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None
    except OSError as exc:   # missing, or not a regular file (a FIFO, a device): nothing is read
        raise ValueError(f"{path}: cannot read it ({exc.strerror or exc})") from None
    import io

    from mwip_ros.yamlio import open_regular
    try:
        raw = open_regular(path, "CSV")
    except OSError as exc:
        raise ValueError(f"{path}: cannot read it ({exc.strerror or exc})") from None
    with io.TextIOWrapper(raw, encoding="utf-8", newline="") as f:
        try:
            first = f.readline(_HEADER_MAX)
        except UnicodeDecodeError as exc:
            raise ValueError(f"{path}: not an mwip_ros CSV (not text: {exc.reason})") from None
        if len(first) >= _HEADER_MAX and not first.endswith("\n"):
            raise ValueError(f"{path}: not an mwip_ros CSV (a header line over {_HEADER_MAX:,} characters)")
        header = [h.strip() for h in next(csv.reader([first]), [])]
        if "t" not in header:
            raise ValueError(f"{path}: not an mwip_ros CSV (no header with a 't' column)")
        if len(header) > MAX_CSV_COLUMNS:
            raise ValueError(f"{path}: not an mwip_ros CSV ({len(header):,} columns; at most {MAX_CSV_COLUMNS})")
        if len(set(header)) != len(header):
            twice = next(h for h in header if header.count(h) > 1)
            raise ValueError(f"{path}: not an mwip_ros CSV (the column {twice!r} appears twice)")
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")   # "input contained no data": said below, in one line
                # a row takes 2 characters a column at least: a file too small to hold more rows than allowed
                # is read as it is (loadtxt would allocate max_rows rows up front)
                cap = max_rows + 1 if size >= (max_rows + 1) * 2 * len(header) else None
                data = np.loadtxt(f, delimiter=",", dtype=float, ndmin=2, max_rows=cap, comments=None,
                                  encoding=None)
        except (ValueError, UnicodeDecodeError) as exc:
            text = " ".join(str(exc).split())
            raise ValueError(f"{path}: not an mwip_ros CSV ({text[:200]})") from None
    if not data.size:
        if not empty_ok:
            raise ValueError(f"{path}: no rows (a header only)")
        data = np.empty((0, len(header)))
    if data.shape[1] != len(header):
        raise ValueError(f"{path}: not an mwip_ros CSV (rows of {data.shape[1]} fields under a header of "
                         f"{len(header)} columns)")
    if len(data) > max_rows:
        raise ValueError(f"{path}: more than {max_rows:,} rows, the most a run may have ({_limit_text()}); "
                         f"cut or decimate it first")
    cols = {name: data[:, i] for i, name in enumerate(header)}   # views: no copy of the table
    check_times(cols["t"], path, ordered)
    h = float(cols["t"][1] - cols["t"][0]) if len(data) > 1 else NAN
    record = _failure_record(cols, path)
    # a CSV says nothing of a fall (metrics.compute judges |theta_b|), but a failed mwip_sim run's does
    return Trajectory(label or str(path), cols, bool(record), h, record)


def _failure_record(cols: dict, path) -> dict:
    """``t_fall``, ``fall_text`` and ``failure`` of a failed mwip_sim run's CSV (its :data:`FAILURE_COLUMNS`, taken out
    of ``cols``), or {}."""
    if not all(c in cols for c in FAILURE_COLUMNS):
        return {}
    t_fall, code = cols.pop(FAILURE_COLUMNS[0]), cols.pop(FAILURE_COLUMNS[1])
    if not len(t_fall) or not math.isfinite(t_fall[0]) or code[0] not in range(1, len(FAILURES)):
        raise ValueError(f"{path}: not an mwip_ros CSV (the columns {', '.join(FAILURE_COLUMNS)} do not say when and "
                         f"why the run failed)")
    why = FAILURES[int(code[0])]
    return {"t_fall": float(t_fall[0]), "failure": why,
            "fall_text": f"{'FELL' if why == 'fall' else 'FAILED'} at t = {t_fall[0]:.3f} s ({why})"}


def check_times(t: np.ndarray, source, ordered: bool = True) -> None:
    """ValueError, one line, unless every ``t`` is finite (and within :data:`MAX_T` s) and (``ordered``) none
    decreases."""
    bad = ~np.isfinite(t) | (np.abs(t) > MAX_T)
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"{source}: t = {float(t[i])!r} s at row {i + 1}: every t must be finite and within "
                         f"{MAX_T:g} s of 0")
    if ordered and len(t) > 1:
        back = np.diff(t) < 0
        if back.any():
            i = int(np.argmax(back)) + 1
            raise ValueError(f"{source}: t decreases at row {i + 1} ({float(t[i - 1])!r} -> {float(t[i])!r} s): "
                             f"not one run's samples in order")


def read_bag_run(bag, label: Optional[str] = None, segment: Optional[int] = None, segments=None) -> Trajectory:
    """Rebuild the run's trajectory from a bag: states, applied torque, estimate, truth (matched by stamp).

    u_k is the torque the plant applied over period k, i.e. the effort reported with
    state k+1 (after the plant's ``torque_limit``).  No state follows the last row: its torque is
    the last recorded wheel_torque_cmd as the plant applies it, clipped at the ``torque_limit``
    when the bag records the plant's parameters; without them the command counts only when its
    magnitude is at most the largest torque the plant applied in the run (so no limit below it
    can have clipped it), else NaN (unknown).  A state resent with the same stamp counts once.
    When the plant measured with noise or delay, the bag has ``true_joint_states`` too: the
    trajectory (and so every metric) is the true one, and the last row's torque is NaN (with an
    actuator delay no message holds it).  With raw sensors and no truth (a robot's bag: the wheel_driver on a
    device) joint_states is the state estimator's estimate: the trajectory is the estimate, and its ``record`` says
    so (``states_from``: ``"estimate"``).  The run's ``record`` is otherwise :func:`plant_record`'s.  A spatial
    plant's bag (backend mujoco) has ``true_pose`` and ``true_wheel_states`` too: the trajectory then has the pose
    columns (x, y, yaw, roll from the one, wheel_left, wheel_right from the other; NaN where a stamp has none); a bag
    without them reads as before.

    A bag of several runs (a reset or a new plant: the stamps go back, :mod:`mwip_ros.bag.segments`) is
    never merged: without ``segment`` it raises :class:`~mwip_ros.bag.segments.SpliceError` (a
    ``ValueError``) naming its runs; with it the trajectory is that run's (0-based; negative from the end).
    ``segments``: the bag's :class:`~mwip_ros.bag.segments.Segments`, when the caller has them already.
    """
    from mwip_ros.bag import check, raw_messages

    try:
        check_size(bag, MAX_BAG_BYTES, "bag")   # before a byte of it is read
    except ValueError as exc:
        raise ValueError(f"{bag}: {exc}") from None
    check(bag)  # a damaged chunk raises BagError naming it: never read as data
    from mwip_ros.bag.segments import Segments, SpliceError
    segs = segments or Segments.from_bag(bag)   # the runs in the bag: the stamps go back at a reset
    messages = raw_messages(bag)
    if segs.spliced:
        if segment is None:
            raise SpliceError(segs.refusal("a report of one run"))
        messages = segs.select(segment)
        label = label or f"{Path(bag).name} [run {range(len(segs))[segment] + 1} of {len(segs)}]"
    states, true_states = _Stamped(5, "joint_states"), _Stamped(5, "true_joint_states")   # x (4), u_prev
    imu, enc = _Stamped(3, "imu/data_raw"), _Stamped(2, "wheel_encoder")   # raw sensors: gyro, f_x, f_z; phi, rate
    est, truth = _Stamped(2, "disturbance_estimate"), _Stamped(2, "lumped_disturbance")
    poses = _Stamped(6, "true_pose")   # a spatial plant's (backend mujoco): x, y, z, yaw, pitch, roll
    wheels = _Stamped(2, "true_wheel_states")   # ... and each wheel's absolute angle: left, right
    odom = _Stamped(3, "odom")   # robot_state's pose (x, y, z = r): its drift from the truth
    cmds: List[float] = []
    logs: List[bytes] = []
    param_events: List[bytes] = []
    for _log_time, topic, data in messages:
        name = leaf(topic)
        if topic == "/rosout":
            if len(logs) < MAX_LOG_MESSAGES:   # the plant logs a few lines a run; a flood beyond is not read
                logs.append(bytes(data))
            continue
        if topic == "/parameter_events":
            if len(param_events) < MAX_LOG_MESSAGES:
                param_events.append(bytes(data))
            continue
        try:
            if name in ("joint_states", "true_joint_states"):
                stamp, x, u_prev = L.parse_joint_state(data)
                (states if name == "joint_states" else true_states).put(bag, stamp, (*x, u_prev))
            elif name == "disturbance_estimate":
                stamp, a, b = L.parse_wrench(data)
                est.put(bag, stamp, (a, b))
            elif name == "lumped_disturbance":
                stamp, a, b = L.parse_wrench(data)
                truth.put(bag, stamp, (a, b))
            elif name == "wheel_torque_cmd":
                cmds[:] = [L.parse_command(data)]   # only the last one is used
            elif name == "data_raw" and topic.endswith("imu/data_raw"):
                stamp, g, fx, fz = L.parse_imu(data)
                imu.put(bag, stamp, (g, fx, fz))
            elif name == "wheel_encoder":
                stamp, phi, rate, _torque = L.parse_encoder(data)
                enc.put(bag, stamp, (phi, rate))
            elif name == "true_pose":
                stamp, pose = L.parse_pose(data)
                poses.put(bag, stamp, pose)
            elif name == "true_wheel_states":
                stamp, angles, _rates = L.parse_wheel_states(data)
                wheels.put(bag, stamp, angles)
            elif name == "odom":
                stamp, x, y, z = L.parse_odometry(data)
                odom.put(bag, stamp, (x, y, z))
        except BadMessage:
            continue  # not the graph's message (a foreign publisher): not part of the run
    estimates = None
    # raw sensors and no truth (a robot, the wheel_driver on a device): joint_states is the state estimator's
    # estimate, and so is every metric of the trajectory; the record says so (states_from)
    estimated_only = bool(len(imu)) and not len(true_states)
    if len(true_states):   # the measurement is what the loop saw; the truth is what happened
        # the torque that acted over the last period is in no message (an actuator delay holds it back)
        if len(imu):   # raw sensors: joint_states is the state_estimator's estimate (its columns *_hat)
            estimates = states
        states, cmds = true_states, []
    if not len(states):
        raise ValueError(f"{bag}: no joint_states messages (is this an mwip_ros bag?)")
    stamps = sorted(states.index)
    t0 = stamps[0]
    record = plant_record(logs, param_events)
    applied = [abs(u) for u in (states.value(s, 4) for s in stamps[1:]) if math.isfinite(u)]
    last_u = _last_torque(cmds[-1] if cmds else NAN, record.get("torque_limit"), max(applied, default=NAN))
    del applied
    # raw sensors or the motor: the torque that acted (joint_states' effort, the encoder's) is u_applied too
    drive = estimates is not None or bool(record.get("motor.enabled"))
    table = TrajectoryTable(raw=estimates is not None, drive=drive, pose=bool(len(poses)))
    nan2, nan3, nan5, nan6 = (NAN, NAN), (NAN,) * 3, (NAN,) * 5, (NAN,) * 6
    for i, s in enumerate(stamps):
        u = states.value(stamps[i + 1], 4) if i + 1 < len(stamps) else last_u
        extra = () if estimates is None else (*imu.get(s, nan3), *enc.get(s, nan2), *estimates.get(s, nan5)[:4])
        pose = Pose(*poses.get(s, nan6), *wheels.get(s, nan2)) if len(poses) else None
        table.append((s - t0) * 1e-9, states.get(s), u, est.get(s, nan2), truth.get(s, nan2), extra=extra, pose=pose)
        if drive:
            table.set_drive(u, math.nan)   # the drive's saturation is in no message
    run = table.trajectory(label or Path(bag).name, "t_fall" in record, NAN)
    check_times(run.t, bag)
    run.h = float(np.median(np.diff(run.t))) if len(run) > 1 else NAN
    run.record = record
    if estimated_only:
        run.record["states_from"] = "estimate"
    if len(odom):
        drift = _bag_odometry_drift(odom, states, poses)
        if drift is not None:
            run.record["odometry"] = drift
    return run


def _bag_odometry_drift(odom: "_Stamped", states: "_Stamped", poses: "_Stamped") -> Optional[dict]:
    """How far ``odom``'s last pose is from the truth (docs/theory.md 6.12) from the first odom stamp to the last one
    that has a state: a spatial plant's ``true_pose`` (x, y) when the bag has it (then also ``true_y_m``); else the
    planar truth, r (theta_w - theta_w0) along x (r = the odom's z, base_link's height) and nothing along y.  None
    when no odom stamp has a state (or, with poses, a pose)."""
    have = poses if len(poses) else states
    both = sorted(s for s in odom.index if have.get(s) is not None)
    if not both:
        return None
    first, last = both[0], both[-1]
    x, y, r = (odom.value(last, k) for k in range(3))
    x0, y0 = odom.value(first, 0), odom.value(first, 1)
    out = {"t_s": (last - first) * 1e-9, "odom_x_m": x - x0}
    if len(poses):
        true_dx, true_dy = (poses.value(last, k) - poses.value(first, k) for k in (0, 1))
        out["true_y_m"] = true_dy
    else:
        true_dx, true_dy = r * (states.value(last, 0) - states.value(first, 0)), 0.0
    return dict(out, true_x_m=true_dx, drift_m=math.hypot(x - x0 - true_dx, y - y0 - true_dy))


class _Stamped:
    """Rows of ``width`` doubles by stamp, in one flat array (a bag of hours: no tuple per message); a message
    resent with the same stamp replaces its row.  At most :data:`MAX_ROWS` stamps (ValueError, one line)."""

    def __init__(self, width: int, topic: str):
        from array import array
        self.width, self.topic = width, topic
        self.index: Dict[int, int] = {}
        self.rows = array("d")

    def __len__(self) -> int:
        return len(self.index)

    def put(self, bag, stamp: int, values) -> None:
        i = self.index.get(stamp)
        if i is None:
            if len(self.index) >= MAX_ROWS:
                _too_long(bag, self.topic)
            self.index[stamp] = len(self.index)
            self.rows.extend(values)
        else:
            w = self.width
            self.rows[i * w:(i + 1) * w] = type(self.rows)("d", values)

    def get(self, stamp: int, default=None):
        i = self.index.get(stamp)
        if i is None:
            return default
        w = self.width
        return tuple(self.rows[i * w:(i + 1) * w])

    def value(self, stamp: int, k: int) -> float:
        return self.rows[self.index[stamp] * self.width + k]


def _too_long(bag, name: str) -> None:
    raise ValueError(f"{bag}: more than {MAX_ROWS:,} {name} messages, the most a run may have "
                     f"({_limit_text()}); not read further")


def _last_torque(cmd: float, limit: Optional[float], largest_applied: float) -> float:
    """The torque the plant applies for the command ``cmd`` (module doc of :func:`read_bag_run`)."""
    if not math.isfinite(cmd):
        return NAN
    if limit is not None:
        return max(-limit, min(limit, cmd)) if limit > 0 else cmd
    return cmd if abs(cmd) <= largest_applied else NAN


def plant_record(logs: List[bytes], param_events: List[bytes]) -> dict:
    """What the plant (or the wheel driver: :data:`ROBOT_SIDE_NODES`) said of its run, from a bag's ``/rosout``
    (rcl_interfaces/Log) and ``/parameter_events`` messages (CDR): ``t_fall`` and ``fall_text`` (its "FALLEN at t =
    ..." line),
    ``fall_angle``, ``duration_s`` (configured; 0 = until stopped), ``interrupted_at``, ``torque_limit``,
    ``motor.enabled``.
    Only the keys the bag holds (a recorder that started late has none of the start)."""
    out: dict = {}
    try:
        from rclpy.serialization import deserialize_message
        from rcl_interfaces.msg import Log, ParameterEvent
    except ImportError:   # no ROS message classes: the table alone tells the run
        return out
    for data in param_events:
        try:
            ev = deserialize_message(data, ParameterEvent)
        except Exception:  # noqa: BLE001 - not a decodable event: not part of the record
            continue
        if ev.node.rsplit("/", 1)[-1] not in ROBOT_SIDE_NODES:
            continue
        for p in list(ev.new_parameters) + list(ev.changed_parameters):
            if p.name in ("torque_limit", "duration_s", "fall_angle") and p.value.type == 3:   # PARAMETER_DOUBLE
                out[p.name] = float(p.value.double_value)
            elif p.name == "motor.enabled" and p.value.type == 1:   # PARAMETER_BOOL
                out[p.name] = bool(p.value.bool_value)
    for data in logs:
        try:
            msg = deserialize_message(data, Log)
        except Exception:  # noqa: BLE001
            continue
        if msg.name.rsplit(".", 1)[-1] not in ROBOT_SIDE_NODES:
            continue
        text = msg.msg
        m = _FALLEN.search(text)
        if m and "t_fall" not in out:
            out["t_fall"], out["fall_text"] = float(m.group(1)), text
            if m.group(2):
                out["fall_angle"] = float(m.group(2))
        m = _START.search(text)
        if m:
            out["duration_s"] = float(m.group(1)) if m.group(1) else 0.0
        m = _INTERRUPTED.search(text)
        if m:
            out["interrupted_at"], out["duration_s"] = float(m.group(1)), float(m.group(2))
    return out


def read_bag_runs(bag, label: Optional[str] = None) -> List[Trajectory]:
    """Every run of a bag, one trajectory each (one for a bag without resets), labelled
    ``<label> [run i of n]`` when there are several (:mod:`mwip_ros.bag.segments`)."""
    from mwip_ros.bag.segments import Segments
    segs = Segments.from_bag(bag)
    n = len(segs)
    if n <= 1:
        return [read_bag_run(bag, label, segments=segs)]
    return [read_bag_run(bag, label and f"{label} [run {i + 1} of {n}]", segment=i, segments=segs) for i in range(n)]


def load_runs(path, label: Optional[str] = None, estimates=None) -> List[Trajectory]:
    """:func:`load_run` for each run of ``path``: a bag may hold several (:func:`read_bag_runs`)."""
    p = Path(path)
    if estimates is None and (p.is_dir() or p.suffix == ".mcap"):
        return read_bag_runs(p, label)
    return [load_run(path, label, estimates)]


def load_run(path, label: Optional[str] = None, estimates=None) -> Trajectory:
    """A bag directory, an .mcap file or a CSV; ``estimates`` is an optional CSV of the observer's
    output (``t, tau_hat1, tau_hat2``) whose values join the run's rows by stamp."""
    p = Path(path)
    if p.is_file() and p.suffix == ".csv":
        run = read_csv(p, label or p.stem)
        missing = [c for c in RUN_COLUMNS if c not in run.columns]
        if missing:
            raise ValueError(f"{path}: no {', '.join(missing)} column{'s' if len(missing) > 1 else ''} (a run's CSV "
                             f"has {', '.join(RUN_COLUMNS)}; tau_hat1, tau_hat2, tau_d1, tau_d2 may be missing)")
        for c in TRAJECTORY_COLUMNS:   # what the source does not know is NaN, as a TrajectoryTable writes it
            if c not in run.columns:
                run.columns[c] = np.full(len(run), NAN)
    elif p.is_dir() or p.suffix == ".mcap":
        run = read_bag_run(p, label)
    else:
        raise ValueError(f"{path}: not a bag directory, .mcap file or .csv file")
    if estimates is not None:
        e = read_csv(estimates, ordered=False, empty_ok=True)
        if "tau_hat1" not in e.columns or "tau_hat2" not in e.columns:
            raise ValueError(f"{estimates}: no tau_hat1, tau_hat2 columns (not the observer's CSV)")
        run = join_estimates(run, zip(e.t, e["tau_hat1"], e["tau_hat2"]))
    return run
