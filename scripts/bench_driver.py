#!/usr/bin/env python3
"""Issue 49's goals through the graph with the wheel_driver, measured (BENCHMARKS.md, "The wheel driver";
docs/hardware.md).

    python scripts/bench_driver.py [--only upkie|moteus|push|estop] [--seconds 60] [--fifo 10] [--json FILE]

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
* **estop**: the emulated robot, 10 s, an e-stop at t = 8 s: the first stop's delay after the transition, in periods.

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
    env = {k: v for k, v in os.environ.items() if k != "ROS_DOMAIN_ID"}
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
    bag = next(p for p in out.iterdir() if p.name.endswith(f"_{law}") and p.is_dir())
    logs = next(p for p in out.iterdir() if p.name.endswith("_logs"))
    summary = logs / f"{law}_driver.json"
    return bag, logs, json.loads(summary.read_text()) if summary.exists() else None


def goals(out: Path, law: str, seconds: float) -> dict:
    """The run's numbers: from its bag (the truth where the robot has one, the estimate else) and its driver."""
    from mwip_ros.robot.closed_loop import summary
    from mwip_ros.runs import read_bag_run
    bag, logs, drv = _files(out, law)
    traj = read_bag_run(bag)
    window = (5.0, seconds) if seconds >= 10 else (seconds / 2, seconds)
    s = summary(traj, window)
    s["driver"] = drv
    s["complete"] = bool(s["upright"] and s["t_end"] >= seconds - 0.003)   # to the run's end, not stopped before
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


def _verdict(g: dict, code: int) -> str:
    """'yes' for a run that stayed up to its end with exit 0; else what happened (a fall, a fault that ended it)."""
    if g["complete"] and code == 0:
        return "yes"
    if not g["upright"]:
        return f"FELL ({g['failure'] or 'at t = %.3f s' % g['t_end']})"
    d = g.get("driver") or {}
    return f"ended at t = {g['t_end']:.3f} s: {d.get('fault_reason')} (exit {code})"


def upkie(tmp: Path, seconds: float, fifo: int, report: dict) -> List[str]:
    rows = ["| Upkie in PyBullet, through the graph | mode | upright | theta_b RMS [5, end] [rad] | worst [rad] | "
            "pitch estimate error RMS [rad] | u RMS [N m] | axle drift largest / final [m] | exit |",
            "|---|---|---|---|---|---|---|---|---|"]
    for mode in ("lockstep", "realtime"):
        out = tmp / f"upkie_{mode}"
        r = run(out, "upkie-pybullet", LAWS, seconds, mode, fifo)
        report.setdefault("upkie", {})[mode] = {"code": r["code"], "load": r["load"]}
        for law in LAWS:
            try:
                g = goals(out, law, seconds)
            except (StopIteration, ValueError) as exc:
                rows.append(f"| {law} | {mode} | no run ({exc}) | | | | | | {r['code']} |")
                continue
            report["upkie"][mode][law] = g
            drift = f"{_num(g['max_drift'], '.4f')} / {_num(g['final_drift'], '.4f')}"
            rows.append(f"| {law} | {mode} | {_verdict(g, r['code'])} | {_num(g['theta_b_rms'], '.5f')} | "
                        f"{_num(g['theta_b_max_abs'], '.5f')} | {_num(g['theta_b_est_err_rms'], '.5f')} | "
                        f"{_num(g['u_rms'], '.4f')} | {drift} | {r['code']} |")
        rows.append(f"| load average (1, 5, 15 min) | {mode} | start {r['load'][0]}, end {r['load'][1]} | | | | | | |")
    return rows


def pushes(tmp: Path, fifo: int, report: dict) -> List[str]:
    rows = [f"| {PUSH_N:g} N forward for {PUSH_FOR:g} s at t = {PUSH_AT:g} s, 12 s | mode | survived | push published "
            "at t [s] | theta_b RMS [8, 12] [rad] | axle drift largest [m] | exit |", "|---|---|---|---|---|---|---|"]
    for mode, laws in (("lockstep", LAWS), ("realtime", ("dscndo",))):
        for law in laws:
            out = tmp / f"push_{mode}_{law}"
            r = run(out, "upkie-pybullet", (law,), 12.0, mode, fifo, push={"force": PUSH_N})
            g = goals(out, law, 12.0)
            from mwip_ros.robot.closed_loop import summary
            from mwip_ros.runs import read_bag_run
            late = summary(read_bag_run(_files(out, law)[0]), (8.0, 12.0))   # after the push
            report.setdefault("push", {})[f"{mode} {law}"] = {"goals": g, "late": late, "applied": r["applied"],
                                                              "code": r["code"], "load": r["load"]}
            applied = ", ".join(f"{t:.3f}" for t in (r["applied"] or [])) or "never"
            rows.append(f"| {law} | {mode} | {_verdict(g, r['code'])} | {applied} | "
                        f"{_num(late['theta_b_rms'], '.5f')} | {_num(g['max_drift'], '.3f')} | {r['code']} |")
    return rows


def moteus(tmp: Path, seconds: float, fifo: int, report: dict) -> List[str]:
    rows = ["| emulated moteus, DSCNDO, realtime 200 Hz | upright | theta_b estimate RMS [5, end] [rad] | "
            "watchdog trips (L, R) | periods run / due (vs seconds x 200) | missed | exchange p50 / p99 [ms] | "
            "read-to-publish p50 / p99 / max [ms] | command age p50 / p99 [ms] | jitter p99 [ms] | "
            "replies missed (L, R) | load (start; end) | exit |", "|" + "---|" * 13]
    for label, emu in (("plain", ""), ("2 ms latency, 1 % loss", "--latency 0.002 --loss 0.01"),
                       ("2 ms latency", "--latency 0.002"), ("1 % loss", "--loss 0.01")):
        out = tmp / f"moteus_{label.split()[0]}_{len(emu)}"
        r = run(out, "emulated-moteus", ("dscndo",), seconds, "realtime", fifo, emulator=emu)
        try:
            g = goals(out, "dscndo", seconds)
        except (StopIteration, ValueError) as exc:
            rows.append(f"| {label} | no run ({exc}) |" + " |" * 11 + f" {r['code']} |")
            continue
        d = g["driver"] or {}
        t, sched = d.get("timing", {}), d.get("schedule") or {}
        due = sched.get("periods_due")
        report.setdefault("moteus", {})[label] = {"goals": g, "code": r["code"], "load": r["load"]}
        rows.append(f"| {label} | {_verdict(g, r['code'])} | {_num(g['theta_b_rms'], '.5f')} | "
                    f"{g.get('watchdog_trips')} | {t.get('periods')} / {due} ({seconds * 200:g}) | {t.get('missed')} | "
                    f"{_ms(t, 'exchange', 'p50')} / {_ms(t, 'exchange', 'p99')} | {_ms(t, 'read_to_publish', 'p50')} / "
                    f"{_ms(t, 'read_to_publish', 'p99')} / {_ms(t, 'read_to_publish', 'max')} | "
                    f"{_ms(t, 'command_age', 'p50')} / {_ms(t, 'command_age', 'p99')} | "
                    f"{_ms(t, 'wake_latency', 'p99')} | {d.get('device_replies_missed')} | {r['load'][0]}; "
                    f"{r['load'][1]} | {r['code']} |")
    return rows


def estop(tmp: Path, fifo: int, report: dict) -> List[str]:
    out = tmp / "estop"
    r = run(out, "emulated-moteus", ("dscndo",), 10.0, "realtime", fifo, push={"estop_at": 8.0})
    _bag, _logs, d = _files(out, "dscndo")
    after = d.get("stop_after_s") or []
    report["estop"] = {"stop_after_s": after, "transitions": d.get("transitions"), "code": r["code"],
                       "load": r["load"]}
    return [f"e-stop at t = 8 s of a 10 s realtime run: {d.get('fault_reason')} latched; first stop written "
            f"{after[0] * 1e3:.3f} ms after the transition ({after[0] / 0.005:.2f} periods); exit {r['code']}"
            if after else f"e-stop: no stop measured (driver {d.get('driver_state')}, exit {r['code']})"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", choices=("upkie", "push", "moteus", "estop"), nargs="*", default=None)
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--fifo", type=int, default=0)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--keep", type=Path, default=None, help="keep the runs' folders here")
    args = ap.parse_args(argv)
    parts = args.only or ["upkie", "push", "moteus", "estop"]
    report: dict = {"seconds": args.seconds, "fifo": args.fifo, "cpus": os.cpu_count()}
    lines = [f"load average at the start: {_load()}; {os.cpu_count()} CPUs; SCHED_FIFO {args.fifo or 'off'}", ""]
    with tempfile.TemporaryDirectory(prefix="bench_driver_") as d:
        tmp = args.keep or Path(d)
        tmp.mkdir(parents=True, exist_ok=True)
        for part in parts:
            if part == "upkie":
                lines += upkie(tmp, args.seconds, args.fifo, report) + [""]
            elif part == "push":
                lines += pushes(tmp, args.fifo, report) + [""]
            elif part == "moteus":
                lines += moteus(tmp, args.seconds, args.fifo, report) + [""]
            else:
                lines += estop(tmp, args.fifo, report) + [""]
            print("\n".join(lines), flush=True)
            lines = []
    print(f"load average at the end: {_load()}")
    if args.json:
        from mwip_ros.core.metrics import json_safe
        args.json.write_text(json.dumps(json_safe(report), indent=1, default=str) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
