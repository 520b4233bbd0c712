"""Runs on disk: a trajectory's CSV, and a recorded bag rebuilt into the same trajectory table.

* :func:`write_csv` / :func:`read_csv`: the columns of :mod:`mwip_ros.core.trajectory`
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
from pathlib import Path
from typing import Dict, List, Optional

import numpy as np

from mwip_ros.core.trajectory import COLUMNS, Trajectory, TrajectoryTable, join_estimates
from mwip_ros.msgs import BadMessage
from mwip_ros.msgs import layouts as L
from mwip_ros.msgs.topics import leaf

__all__ = ["write_csv", "read_csv", "read_bag_run", "load_run", "plant_record", "PLANT_NODE"]

PLANT_NODE = "plant_sim"
# what plant_sim logs (mwip_ros.nodes.plant_sim): its start (the configured duration), a fall, an interruption
_FALLEN = re.compile(r"FALLEN at t = ([-+0-9.eE]+) s(?:: \|theta_b\| = [-+0-9.eE]+ > fall_angle ([-+0-9.eE]+))?")
_START = re.compile(r"(?:lockstep|realtime) plant: h = .*?, (?:([-+0-9.eE]+) s|until stopped), seed")
_INTERRUPTED = re.compile(r"interrupted at t = ([-+0-9.eE]+) s of ([-+0-9.eE]+) s")

NAN = math.nan


def write_csv(run: Trajectory, path) -> None:
    """The columns ``run`` has, in the trajectory table's order (then ``stamp``, a realtime plant's message
    stamps in seconds when they are not ``t``), floats written exactly (repr)."""
    names = [c for c in (*COLUMNS, "stamp") if c in run.columns]
    with open(path, "w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(names)
        for row in zip(*(run.columns[c] for c in names)):
            w.writerow([repr(float(x)) for x in row])


def read_csv(path, label: Optional[str] = None) -> Trajectory:
    """Read a CSV written by :func:`write_csv` (``mwip_sim --csv``, ``plant_sim``'s or the observer's ``csv``)."""
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    if not rows or "t" not in rows[0]:
        raise ValueError(f"{path}: not an mwip_ros CSV (no header with a 't' column)")
    header = rows[0]
    try:
        data = np.array([[float(x) for x in r] for r in rows[1:]], dtype=float).reshape(-1, len(header))
    except ValueError as exc:
        raise ValueError(f"{path}: not an mwip_ros CSV ({exc})") from None
    cols = {name: data[:, i] for i, name in enumerate(header)}
    h = float(cols["t"][1] - cols["t"][0]) if len(data) > 1 else NAN
    return Trajectory(label or str(path), cols, False, h)  # a CSV does not say; metrics.compute judges |theta_b|


def read_bag_run(bag, label: Optional[str] = None) -> Trajectory:
    """Rebuild the run's trajectory from a bag: states, applied torque, estimate, truth (matched by stamp).

    u_k is the torque the plant applied over period k, i.e. the effort reported with
    state k+1 (after the plant's ``torque_limit``).  No state follows the last row: its torque is
    the last recorded wheel_torque_cmd as the plant applies it, clipped at the ``torque_limit``
    when the bag records the plant's parameters; without them the command counts only when its
    magnitude is at most the largest torque the plant applied in the run (so no limit below it
    can have clipped it), else NaN (unknown).  A state resent with the same stamp counts once.
    When the plant measured with noise or delay, the bag has ``true_joint_states`` too: the
    trajectory (and so every metric) is the true one, and the last row's torque is NaN (with an
    actuator delay no message holds it).  The run's ``record`` is :func:`plant_record`'s.
    """
    from mwip_ros.bag import check, raw_messages

    check(bag)  # a damaged chunk raises BagError naming it: never read as data
    states: Dict[int, tuple] = {}
    true_states: Dict[int, tuple] = {}
    est: Dict[int, tuple] = {}
    truth: Dict[int, tuple] = {}
    cmds: List[float] = []
    logs: List[tuple] = []
    param_events: List[bytes] = []
    for _log_time, topic, data in raw_messages(bag):
        name = leaf(topic)
        if topic == "/rosout":
            logs.append(bytes(data))
            continue
        if topic == "/parameter_events":
            param_events.append(bytes(data))
            continue
        try:
            if name in ("joint_states", "true_joint_states"):
                stamp, x, u_prev = L.parse_joint_state(data)
                (states if name == "joint_states" else true_states)[stamp] = (x, u_prev)
            elif name == "disturbance_estimate":
                stamp, a, b = L.parse_wrench(data)
                est[stamp] = (a, b)
            elif name == "lumped_disturbance":
                stamp, a, b = L.parse_wrench(data)
                truth[stamp] = (a, b)
            elif name == "wheel_torque_cmd":
                cmds.append(L.parse_command(data))
        except BadMessage:
            continue  # not the graph's message (a foreign publisher): not part of the run
    if true_states:   # the measurement is what the loop saw; the truth is what happened
        # the torque that acted over the last period is in no message (an actuator delay holds it back)
        states, cmds = true_states, []
    if not states:
        raise ValueError(f"{bag}: no joint_states messages (is this an mwip_ros bag?)")
    stamps = sorted(states)
    t0 = stamps[0]
    record = plant_record(logs, param_events)
    applied = [abs(states[s][1]) for s in stamps[1:] if math.isfinite(states[s][1])]
    last_u = _last_torque(cmds[-1] if cmds else NAN, record.get("torque_limit"), max(applied, default=NAN))
    table = TrajectoryTable()
    for i, s in enumerate(stamps):
        u = states[stamps[i + 1]][1] if i + 1 < len(stamps) else last_u
        table.append((s - t0) * 1e-9, states[s][0], u, est.get(s, (NAN, NAN)), truth.get(s, (NAN, NAN)))
    run = table.trajectory(label or Path(bag).name, "t_fall" in record, NAN)
    run.h = float(np.median(np.diff(run.t))) if len(run) > 1 else NAN
    run.record = record
    return run


def _last_torque(cmd: float, limit: Optional[float], largest_applied: float) -> float:
    """The torque the plant applies for the command ``cmd`` (module doc of :func:`read_bag_run`)."""
    if not math.isfinite(cmd):
        return NAN
    if limit is not None:
        return max(-limit, min(limit, cmd)) if limit > 0 else cmd
    return cmd if abs(cmd) <= largest_applied else NAN


def plant_record(logs: List[bytes], param_events: List[bytes]) -> dict:
    """What the plant said of its run, from a bag's ``/rosout`` (rcl_interfaces/Log) and
    ``/parameter_events`` messages (CDR): ``t_fall`` and ``fall_text`` (its "FALLEN at t = ..." line),
    ``fall_angle``, ``duration_s`` (configured; 0 = until stopped), ``interrupted_at``, ``torque_limit``.
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
        if ev.node.rsplit("/", 1)[-1] != PLANT_NODE:
            continue
        for p in list(ev.new_parameters) + list(ev.changed_parameters):
            if p.name in ("torque_limit", "duration_s", "fall_angle") and p.value.type == 3:   # PARAMETER_DOUBLE
                out[p.name] = float(p.value.double_value)
    for data in logs:
        try:
            msg = deserialize_message(data, Log)
        except Exception:  # noqa: BLE001
            continue
        if msg.name.rsplit(".", 1)[-1] != PLANT_NODE:
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


def load_run(path, label: Optional[str] = None, estimates=None) -> Trajectory:
    """A bag directory, an .mcap file or a CSV; ``estimates`` is an optional CSV of the observer's
    output (``t, tau_hat1, tau_hat2``) whose values join the run's rows by stamp."""
    p = Path(path)
    if p.is_file() and p.suffix == ".csv":
        run = read_csv(p, label or p.stem)
    elif p.is_dir() or p.suffix == ".mcap":
        run = read_bag_run(p, label)
    else:
        raise ValueError(f"{path}: not a bag directory, .mcap file or .csv file")
    if estimates is not None:
        e = read_csv(estimates)
        if "tau_hat1" not in e.columns or "tau_hat2" not in e.columns:
            raise ValueError(f"{estimates}: no tau_hat1, tau_hat2 columns (not the observer's CSV)")
        run = join_estimates(run, zip(e.t, e["tau_hat1"], e["tau_hat2"]))
    return run
