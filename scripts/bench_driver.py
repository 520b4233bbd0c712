#!/usr/bin/env python3
"""Issue 49's goals through the graph with the wheel_driver, measured (BENCHMARKS.md, "The wheel driver";
docs/hardware.md).

    python scripts/bench_driver.py [--only upkie|moteus|push|mock|estop] [--seconds 60] [--laws dscndo,lqr_ndo,mpc_ndo]
                                   [--modes lockstep,realtime] [--fifo 10] [--json FILE] [--keep DIR]

Each run is ``scripts/run_experiment.sh --robot ...`` as a user runs it (its bags, logs and report in a temporary
folder), read back from its bag and the driver's summary:

* **upkie**: Upkie in its own PyBullet (``--robot upkie-pybullet``, config/paper.yaml config/upkie.yaml: 0.05 rad off
  upright), DSCNDO, LQR+NDO and MPC+NDO, ``--seconds`` each, in lockstep and in realtime at 200 Hz: upright, theta_b's
  RMS over [5, seconds] s (PyBullet's truth), the axle's largest and final distance from its start (``true_pose``),
  the estimator's pitch error; realtime also the driver's period timing;
* **push**: the same robot, 12 s, a forward push on the torso of docs/laws.md's first size scaled to Upkie's mass
  (1 kN on 340 kg: 15.7 N) held 0.1 s from t = 5 s (``external_wrench`` force.x, published by this script on the
  run's domain, timed by ``/clock`` in lockstep and by the reads' stamps in realtime): survived or not, per law;
* **moteus**: the emulated moteus robot (``--robot emulated-moteus``: Upkie's rigid model behind two emulated
  controllers on a pty, its IMU at 400 Hz), DSCNDO realtime at 200 Hz, ``--seconds``, plain and with 2 ms of added
  latency and 1 % frame loss: upright (the estimate: a device has no truth), the controllers' watchdog trips, the
  driver's period (read-to-publish, the exchange, the periods run against seconds x 200);
* **mock**: the mock wheels (``--robot mock``: commands mirrored, nothing moves; the transport costs nothing),
  DSCNDO realtime at 200 Hz, ``--seconds``: the driver's own period (read-to-publish, the periods run against
  seconds x 200), the wiring's check;
* **estop**: the emulated robot, 10 s, an e-stop at t = 8 s: the first stop's delay after the transition, in periods.

Each law's run is judged on its own: its exit is its driver's (``exit_code`` in the driver's summary), not
run_experiment.sh's, which is 3 when any law of the invocation fell.  Each goal is a verdict (``meets``, ``MISSES``)
only from numbers the run has: a number that is missing or NaN is ``unmeasured``, never a pass.  A robot without a
truth (the emulated moteus) is judged on the state estimator's estimate (``joint_states``), and the table says so.

``--seconds`` (or ``--duration``): each run's length (default 60, the goals'); ``--laws`` and ``--modes`` pick the
Upkie runs (a short check: ``--only upkie --modes lockstep --laws dscndo --seconds 10``).  The runs use your
``ROS_DOMAIN_ID`` when it is set (each in turn: run_experiment.sh holds it for the run), else a free one each.

``--fifo P``: every realtime run under SCHED_FIFO P (run_experiment.sh --realtime-priority: the loop's nodes, the
driver, the emulator).  The machine's load is printed at each run's start and end.  Markdown to stdout, progress to
stderr.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import re
import subprocess
import sys
import tempfile
import threading
from pathlib import Path
from typing import List, Optional

REPO = Path(__file__).resolve().parent.parent
LAWS = ("dscndo", "lqr_ndo", "mpc_ndo")
PUSH_N = 15.7          # 1 kN on the paper's 340 kg robot, scaled to Upkie's 5.34 kg (docs/hardware-upkie.md)
PUSH_AT, PUSH_FOR = 5.0, 0.1
RATE_HZ = 200.0        # the goals' control rate
# the goals (issue 49)
PITCH_RMS_MAX = 0.01   # theta_b RMS over [5, end] s [rad]
DRIFT_MAX = 0.1        # the axle's largest distance from its start [m]
READ_TO_PUBLISH_P99_MAX_MS = 1.0   # the driver's own cost, beyond the transport's
PERIODS_TOL = 0.002    # periods run within 0.2 % of seconds x rate
END_SLACK_S = 0.1      # a realtime device's bag ends this close to the planned end (its stamps start at its first
                       # estimate, not at the driver's period 0): the window then ends at the bag's end


def _say(text: str) -> None:
    print(f"bench_driver: {text}", file=sys.stderr, flush=True)


def _load() -> str:
    return " ".join(f"{v:.1f}" for v in os.getloadavg())


class Pusher:
    """A participant on the run's domain that holds ``force`` [N] forward on the torso over [at, at + duration) of
    the run's time (lockstep: /clock; realtime: the driver's reads, from its first stamp), then releases it; or that
    asserts the e-stop at ``estop_at``."""

    def __init__(self, domain: str, realtime: bool, force: float = 0.0, at: float = PUSH_AT,
                 duration: float = PUSH_FOR, estop_at: Optional[float] = None):
        self.domain, self.realtime, self.force, self.at, self.duration = domain, realtime, force, at, duration
        self.estop_at = estop_at
        self.applied: List[float] = []   # the run's times of the pushes' and the release's publication
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        os.environ["ROS_DOMAIN_ID"] = self.domain
        os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        import rclpy
        from geometry_msgs.msg import Wrench
        from rosgraph_msgs.msg import Clock
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Bool

        from mwip_ros.msgs.qos import GRAPH_QOS, INPUT_QOS, REALTIME_INPUT_QOS
        ctx = rclpy.Context()
        rclpy.init(context=ctx)
        node = rclpy.create_node("bench_pusher", context=ctx)
        wrench = node.create_publisher(Wrench, "external_wrench", INPUT_QOS)
        estop = node.create_publisher(Bool, "emergency_stop", INPUT_QOS)
        state = {"t0": None, "stage": 0}

        def at(t: float) -> None:
            if self.estop_at is not None:
                if state["stage"] == 0 and t >= self.estop_at:
                    estop.publish(Bool(data=True))
                    self.applied.append(t)
                    state["stage"] = 1
                return
            if state["stage"] == 0 and t >= self.at:
                w = Wrench()
                w.force.x = self.force
                wrench.publish(w)
                self.applied.append(t)
                state["stage"] = 1
            elif state["stage"] == 1 and t >= self.at + self.duration:
                wrench.publish(Wrench())
                self.applied.append(t)
                state["stage"] = 2

        if self.realtime:
            def on_read(m) -> None:
                s = m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec
                state["t0"] = state["t0"] if state["t0"] is not None else s
                at(s - state["t0"])
            node.create_subscription(JointState, "wheel_encoder", on_read, REALTIME_INPUT_QOS)
        else:
            node.create_subscription(Clock, "/clock", lambda m: at(m.clock.sec + 1e-9 * m.clock.nanosec), GRAPH_QOS)
        executor = rclpy.executors.SingleThreadedExecutor(context=ctx)
        executor.add_node(node)
        while not self.stop.is_set():
            executor.spin_once(timeout_sec=0.01)
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)

    def close(self) -> None:
        self.stop.set()
        self.thread.join(10)


def run(out: Path, robot: str, laws, seconds: float, mode: str, fifo: int = 0, emulator: str = "",
        push: Optional[dict] = None) -> dict:
    """One run_experiment.sh; its output, exit code, folders and the pusher's times."""
    args = ["bash", str(REPO / "scripts" / "run_experiment.sh"), "--robot", robot, "--laws", ",".join(laws),
            "--duration", f"{seconds:g}", "--mode", mode, "--out", str(out)]
    if fifo and mode == "realtime":
        args += ["--realtime-priority", str(fifo)]
    if emulator:
        args += ["--emulator-options", emulator]
    env = dict(os.environ)   # the user's ROS_DOMAIN_ID if set (run_experiment.sh holds it per run), else a free one
    load0 = _load()
    _say(f"{robot} {','.join(laws)} {mode} {seconds:g} s {emulator} (load {load0})")
    p = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    lines, pusher = [], None
    for line in p.stdout:
        lines.append(line)
        m = re.match(r"run_experiment: ROS_DOMAIN_ID=(\d+)", line)
        if m and push is not None:
            pusher = Pusher(m.group(1), mode == "realtime", **push)
    code = p.wait()
    if pusher is not None:
        pusher.close()
    return {"code": code, "output": "".join(lines), "load": (load0, _load()),
            "applied": pusher.applied if pusher else None}


def _files(out: Path, law: str):
    bag = next((p for p in out.iterdir() if p.name.endswith(f"_{law}") and p.is_dir()), None) if out.is_dir() else None
    logs = next((p for p in out.iterdir() if p.name.endswith("_logs")), None) if out.is_dir() else None
    if bag is None or logs is None:   # run_experiment.sh stopped before this law (a node failed in an earlier one)
        raise ValueError(f"no bag of {law} under {out}")
    summary = logs / f"{law}_driver.json"
    return bag, logs, json.loads(summary.read_text()) if summary.exists() else None


def window_for(seconds: float, t_end: float) -> tuple:
    """The metrics window: [5, seconds] s (the second half of a run shorter than 10 s), ending at the bag's end when
    that is within :data:`END_SLACK_S` before ``seconds`` (a realtime device's bag starts at its first estimate)."""
    start = 5.0 if seconds >= 10 else seconds / 2
    end = t_end if math.isfinite(t_end) and seconds - END_SLACK_S <= t_end < seconds else seconds
    return start, end


def goals(out: Path, law: str, seconds: float, code: Optional[int] = None) -> dict:
    """The run's numbers: from its bag (the truth where the robot has one, the estimate else: ``judged_on``) and its
    driver.  ``exit`` is the law's own: its driver's exit code (``code``, run_experiment.sh's, only when the driver
    wrote no summary); ``complete``: upright, exit 0 (the driver ran to its planned end) and the bag covers the
    window."""
    from mwip_ros.robot.closed_loop import summary
    from mwip_ros.runs import read_bag_run
    bag, logs, drv = _files(out, law)
    traj = read_bag_run(bag)
    t_end = float(traj.t[-1]) if len(traj) else math.nan
    s = summary(traj, window_for(seconds, t_end))
    s["driver"] = drv
    s["exit"] = drv["exit_code"] if drv is not None and drv.get("exit_code") is not None else code
    s["complete"] = bool(s["upright"] and s["exit"] == 0 and s["covers_window"])
    emu = logs / f"{law}_moteus_emulator.log"
    if emu.exists():
        m = re.search(r"watchdog trips (\d+) left (\d+) right", emu.read_text())
        s["watchdog_trips"] = (int(m.group(1)), int(m.group(2))) if m else None
        s["emulator"] = emu.read_text().strip().splitlines()[-1]
    return s


def _ms(t: dict, f: str, q: str) -> str:
    v = t.get(f"{f}_ms_{q}")
    return "-" if v is None else f"{v:.2f}"


def _num(v, fmt: str) -> str:
    return format(v, fmt) if isinstance(v, float) and math.isfinite(v) else "-"


def _verdict(g: dict) -> str:
    """'yes' for a run that stayed up to its planned end (its driver's exit 0); else what happened: a fall, the fault
    that ended it (its reason and detail), or the exit code that says how it ended (a table cell: ``|`` escaped)."""
    return _what_happened(g).replace("|", "\\|")


def _what_happened(g: dict) -> str:
    if g["complete"]:
        return "yes"
    if not g["upright"]:
        return f"FELL ({g['failure'] or 'at t = %.3f s' % g['t_end']})"
    d = g.get("driver") or {}
    t_end = _num(g["t_end"], ".3f")
    if d.get("fault_reason"):
        return f"ended at t = {t_end} s in fault {d['fault_reason']}: {d.get('fault_detail')} (exit {g['exit']})"
    if g["exit"] == 0:
        return f"bag ends at t = {t_end} s, short of the window (exit 0)"
    return f"ended at t = {t_end} s (exit {g['exit']}{', no driver summary' if not d else ''})"


def _check(value, limit: float) -> str:
    """A goal's verdict: ``meets`` (value <= limit), ``MISSES``, or ``unmeasured`` (missing or NaN: never a pass)."""
    if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value):
        return "unmeasured"
    return "meets" if value <= limit else "MISSES"


def upkie_goals(g: dict) -> str:
    """Upright to the end, theta_b RMS over the window and the axle's largest drift against the goals."""
    rms, drift = _check(g["theta_b_rms"], PITCH_RMS_MAX), _check(g["max_drift"], DRIFT_MAX)
    if not g["complete"]:
        return "MISSES (not upright to its end)"
    if g["judged_on"] != "truth":
        return "unmeasured (no truth)"
    return "meets" if rms == drift == "meets" else f"pitch RMS {rms}, drift {drift}"


def _period_checks(d: Optional[dict], seconds: float) -> dict:
    """The driver's period against the goals: the periods run within 0.2 % of seconds x 200, the read-to-publish p99
    within 1 ms (``unmeasured`` without the driver's summary)."""
    t = (d or {}).get("timing") or {}
    periods, due = t.get("periods"), seconds * RATE_HZ
    return {"periods": _check(abs(periods - due) / due if isinstance(periods, int) else None, PERIODS_TOL),
            "read-to-publish": _check(t.get("read_to_publish_ms_p99"), READ_TO_PUBLISH_P99_MAX_MS)}


def _goals_text(checks: dict) -> str:
    return "meets" if all(v == "meets" for v in checks.values()) else ", ".join(
        f"{k} {v}" for k, v in checks.items() if v != "meets")


def period_goals(d: Optional[dict], seconds: float) -> str:
    """:func:`_period_checks` in one cell: ``meets``, or the goals not met and how."""
    return _goals_text(_period_checks(d, seconds))


def moteus_goals(g: dict, seconds: float) -> str:
    """Upright to the end (on the estimate), 0 watchdog trips, the periods run within 0.2 % of seconds x 200, the
    read-to-publish p99 within 1 ms."""
    trips = g.get("watchdog_trips")
    return _goals_text({"upright": "meets" if g["complete"] else "MISSES",
                        "watchdog": "unmeasured" if trips is None else ("meets" if sum(trips) == 0 else "MISSES"),
                        **_period_checks(g.get("driver"), seconds)})


def upkie(tmp: Path, seconds: float, fifo: int, report: dict, laws=LAWS, modes=("lockstep", "realtime")) -> List[str]:
    rows = ["| Upkie in PyBullet, through the graph | mode | upright to the end | theta_b RMS [5, end] [rad] | "
            "worst [rad] | judged on | pitch estimate error RMS [rad] | u RMS [N m] | axle drift largest / final [m] | "
            f"goals (RMS <= {PITCH_RMS_MAX:g} rad, drift <= {DRIFT_MAX:g} m) | exit |",
            "|" + "---|" * 11]
    for mode in modes:
        out = tmp / f"upkie_{mode}"
        r = run(out, "upkie-pybullet", laws, seconds, mode, fifo)
        report.setdefault("upkie", {})[mode] = {"code": r["code"], "load": r["load"]}
        for law in laws:
            try:
                g = goals(out, law, seconds, r["code"])
            except ValueError as exc:
                rows.append(f"| {law} | {mode} | no run ({exc}) |" + " |" * 6 + f" unmeasured | {r['code']} |")
                continue
            report["upkie"][mode][law] = g
            drift = f"{_num(g['max_drift'], '.4f')} / {_num(g['final_drift'], '.4f')}"
            rows.append(f"| {law} | {mode} | {_verdict(g)} | {_num(g['theta_b_rms'], '.5f')} | "
                        f"{_num(g['theta_b_max_abs'], '.5f')} | {g['judged_on']} | "
                        f"{_num(g['theta_b_est_err_rms'], '.5f')} | {_num(g['u_rms'], '.4f')} | {drift} | "
                        f"{upkie_goals(g)} | {g['exit']} |")
        rows.append(f"| load average (1, 5, 15 min) | {mode} | start {r['load'][0]}, end {r['load'][1]} |"
                    + " |" * 8)
    return rows


def pushes(tmp: Path, fifo: int, report: dict) -> List[str]:
    rows = [f"| {PUSH_N:g} N forward for {PUSH_FOR:g} s at t = {PUSH_AT:g} s, 12 s | mode | survived | push published "
            "at t [s] | theta_b RMS [8, 12] [rad] | axle drift largest [m] | exit |", "|---|---|---|---|---|---|---|"]
    for mode, laws in (("lockstep", LAWS), ("realtime", LAWS)):
        for law in laws:
            out = tmp / f"push_{mode}_{law}"
            r = run(out, "upkie-pybullet", (law,), 12.0, mode, fifo, push={"force": PUSH_N})
            try:
                g = goals(out, law, 12.0, r["code"])
            except ValueError as exc:
                rows.append(f"| {law} | {mode} | no run ({exc}) | | | | {r['code']} |")
                continue
            from mwip_ros.robot.closed_loop import summary
            from mwip_ros.runs import read_bag_run
            late = summary(read_bag_run(_files(out, law)[0]), (8.0, 12.0))   # after the push
            report.setdefault("push", {})[f"{mode} {law}"] = {"goals": g, "late": late, "applied": r["applied"],
                                                              "code": r["code"], "load": r["load"]}
            applied = ", ".join(f"{t:.3f}" for t in (r["applied"] or [])) or "never"
            rows.append(f"| {law} | {mode} | {_verdict(g)} | {applied} | "
                        f"{_num(late['theta_b_rms'], '.5f')} | {_num(g['max_drift'], '.3f')} | {g['exit']} |")
    return rows


def moteus(tmp: Path, seconds: float, fifo: int, report: dict) -> List[str]:
    rows = ["| emulated moteus, DSCNDO, realtime 200 Hz | upright to the end (on the estimate) | "
            "theta_b RMS [5, end] [rad] (judged on) | "
            "watchdog trips (L, R) | periods run / due (vs seconds x 200) | missed | exchange p50 / p99 [ms] | "
            "read-to-publish p50 / p99 / max [ms] | command age p50 / p99 [ms] | jitter p99 [ms] | "
            "replies missed (L, R) | load (start; end) | goals | exit |", "|" + "---|" * 14]
    for label, emu in (("plain", ""), ("2 ms latency, 1 % loss", "--latency 0.002 --loss 0.01"),
                       ("2 ms latency", "--latency 0.002"), ("1 % loss", "--loss 0.01")):
        out = tmp / f"moteus_{label.split()[0]}_{len(emu)}"
        r = run(out, "emulated-moteus", ("dscndo",), seconds, "realtime", fifo, emulator=emu)
        try:
            g = goals(out, "dscndo", seconds, r["code"])
        except ValueError as exc:
            rows.append(f"| {label} | no run ({exc}) |" + " |" * 10 + f" unmeasured | {r['code']} |")
            continue
        d = g["driver"] or {}
        t, sched = d.get("timing", {}), d.get("schedule") or {}
        due = sched.get("periods_due")
        report.setdefault("moteus", {})[label] = {"goals": g, "code": r["code"], "load": r["load"]}
        rows.append(f"| {label} | {_verdict(g)} | {_num(g['theta_b_rms'], '.5f')} ({g['judged_on']}) | "
                    f"{g.get('watchdog_trips')} | {t.get('periods')} / {due} ({seconds * 200:g}) | {t.get('missed')} | "
                    f"{_ms(t, 'exchange', 'p50')} / {_ms(t, 'exchange', 'p99')} | {_ms(t, 'read_to_publish', 'p50')} / "
                    f"{_ms(t, 'read_to_publish', 'p99')} / {_ms(t, 'read_to_publish', 'max')} | "
                    f"{_ms(t, 'command_age', 'p50')} / {_ms(t, 'command_age', 'p99')} | "
                    f"{_ms(t, 'wake_latency', 'p99')} | {d.get('device_replies_missed')} | {r['load'][0]}; "
                    f"{r['load'][1]} | {moteus_goals(g, seconds)} | {g['exit']} |")
    return rows


def mock(tmp: Path, seconds: float, fifo: int, report: dict) -> List[str]:
    rows = ["| mock wheels, DSCNDO, realtime 200 Hz | ran to the end | periods run / due (vs seconds x 200) | missed | "
            "read-to-publish p50 / p99 / max [ms] | command age p50 / p99 [ms] | jitter p99 [ms] | load (start; end) | "
            "goals | exit |", "|" + "---|" * 10]
    out = tmp / "mock"
    r = run(out, "mock", ("dscndo",), seconds, "realtime", fifo)
    try:
        g = goals(out, "dscndo", seconds, r["code"])
    except ValueError as exc:
        return rows + [f"| mock | no run ({exc}) |" + " |" * 6 + f" unmeasured | {r['code']} |"]
    d = g["driver"] or {}
    t, sched = d.get("timing", {}), d.get("schedule") or {}
    report["mock"] = {"goals": g, "code": r["code"], "load": r["load"]}
    rows.append(f"| mock | {_verdict(g)} | {t.get('periods')} / {sched.get('periods_due')} ({seconds * RATE_HZ:g}) | "
                f"{t.get('missed')} | {_ms(t, 'read_to_publish', 'p50')} / {_ms(t, 'read_to_publish', 'p99')} / "
                f"{_ms(t, 'read_to_publish', 'max')} | {_ms(t, 'command_age', 'p50')} / "
                f"{_ms(t, 'command_age', 'p99')} | {_ms(t, 'wake_latency', 'p99')} | {r['load'][0]}; {r['load'][1]} | "
                f"{period_goals(d, seconds)} | {g['exit']} |")
    return rows


def estop(tmp: Path, fifo: int, report: dict) -> List[str]:
    out = tmp / "estop"
    r = run(out, "emulated-moteus", ("dscndo",), 10.0, "realtime", fifo, push={"estop_at": 8.0})
    try:
        _bag, _logs, d = _files(out, "dscndo")
    except ValueError:
        d = None
    if d is None:
        return [f"e-stop: no run (no bag or no driver summary; exit {r['code']})"]
    after = d.get("stop_after_s") or []
    report["estop"] = {"stop_after_s": after, "transitions": d.get("transitions"), "code": r["code"],
                       "applied": r["applied"], "fault_reason": d.get("fault_reason"), "load": r["load"]}
    return [estop_line(d, r["applied"], r["code"])]


def estop_line(d: dict, applied, code: int) -> str:
    """The e-stop's row: the first stop's delay after the transition, only when the e-stop is what took the driver
    out of enabled (the machine keeps the first reason; ``stop_after_s[0]`` is that transition's); else what did, and
    the e-stop unmeasured."""
    after = d.get("stop_after_s") or []
    sent = f"published at t = {', '.join(f'{t:.3f}' for t in applied)} s" if applied else "never published"
    if d.get("fault_reason") != "emergency_stop" or not after:
        what = (f"the driver latched {d.get('fault_reason')} first ({d.get('fault_detail')})" if d.get("fault_reason")
                else f"no stop measured (driver {d.get('driver_state')})")
        return f"e-stop: unmeasured: {what}; the e-stop {sent}; exit {code}"
    return (f"e-stop at t = 8 s of a 10 s realtime run ({sent}): emergency_stop latched; first "
            f"stop written {after[0] * 1e3:.3f} ms after the transition ({after[0] * RATE_HZ:.2f} periods: "
            f"{'meets' if after[0] * RATE_HZ <= 1.0 else 'MISSES'} within one period); exit {code}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", choices=("upkie", "push", "moteus", "mock", "estop"), nargs="*", default=None)
    ap.add_argument("--seconds", "--duration", type=float, default=60.0,
                    help="each run's length [s] (the push and e-stop runs are 12 s and 10 s)")
    ap.add_argument("--laws", default=",".join(LAWS), help="the Upkie runs' laws (comma separated)")
    ap.add_argument("--modes", default="lockstep,realtime", help="the Upkie runs' modes (comma separated)")
    ap.add_argument("--fifo", type=int, default=0)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--keep", type=Path, default=None, help="keep the runs' folders here")
    args = ap.parse_args(argv)
    parts = args.only or ["upkie", "push", "moteus", "mock", "estop"]
    report: dict = {"seconds": args.seconds, "fifo": args.fifo, "cpus": os.cpu_count()}
    lines = [f"load average at the start: {_load()}; {os.cpu_count()} CPUs; SCHED_FIFO {args.fifo or 'off'}", ""]
    with tempfile.TemporaryDirectory(prefix="bench_driver_") as d:
        tmp = args.keep or Path(d)
        tmp.mkdir(parents=True, exist_ok=True)
        for part in parts:
            if part == "upkie":
                lines += upkie(tmp, args.seconds, args.fifo, report, tuple(args.laws.split(",")),
                               tuple(args.modes.split(","))) + [""]
            elif part == "push":
                lines += pushes(tmp, args.fifo, report) + [""]
            elif part == "moteus":
                lines += moteus(tmp, args.seconds, args.fifo, report) + [""]
            elif part == "mock":
                lines += mock(tmp, args.seconds, args.fifo, report) + [""]
            else:
                lines += estop(tmp, args.fifo, report) + [""]
            print("\n".join(lines), flush=True)
            lines = []
    print(f"load average at the end: {_load()}")
    if args.json:
        from mwip_ros.core.closed_loop.metrics import json_safe
        args.json.write_text(json.dumps(json_safe(report), indent=1, default=str) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
