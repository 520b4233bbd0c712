#!/usr/bin/env python3
"""The round trip of one MoteusBackend step over a pty to mwip_moteus_emulator, and whether a rate holds.

    python scripts/moteus_roundtrip.py [--rate 200] [--duration 20] [--latency S] [--jitter S] [--loss F]
                                       [--reply-timeout S] [--fifo PRIO] [--json FILE]

Starts the emulator (its own process, no IMU: nothing else on the machine's ROS), opens the backend on its pty and
steps it at ``--rate`` on the wall clock (absolute deadlines, as a driver node keeps its period) with a constant
torque, then reports each step's round trip (median, p99, max), the replies missed, the periods overrun (a step that
ended after the next period's start) and the periods run against the wall clock's count, up to a fault if the
backend latches one (the run stops there).  ``--fifo PRIO`` runs both
processes under SCHED_FIFO at PRIO (root or CAP_SYS_NICE).  Exit 0; 1 when the backend latched a fault.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import signal
import statistics
import subprocess
import sys
import time


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rate", type=float, default=200.0, help="steps per second (default 200)")
    ap.add_argument("--duration", type=float, default=20.0, help="seconds of stepping (default 20)")
    ap.add_argument("--latency", type=float, default=0.0, help="the emulator's added latency [s]")
    ap.add_argument("--jitter", type=float, default=0.0, help="the emulator's jitter [s]")
    ap.add_argument("--loss", type=float, default=0.0, help="the emulator's frame loss (fraction)")
    ap.add_argument("--reply-timeout", type=float, default=0.004, help="the backend's reply_timeout [s]")
    ap.add_argument("--fifo", type=int, default=0, help="SCHED_FIFO priority of both processes (0: none)")
    ap.add_argument("--json", default=None, help="also write the figures to this file")
    args = ap.parse_args(argv)

    from mwip_ros.robot import Command
    from mwip_ros.robot.moteus_backend import MoteusBackend, MoteusConfig

    cmd = [sys.executable, "-m", "mwip_ros.cli.moteus_emulator", "--imu-rate", "0", "--latency", str(args.latency),
           "--jitter", str(args.jitter), "--loss", str(args.loss)]
    if args.fifo:
        cmd = ["chrt", "-f", str(args.fifo), *cmd]
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(args.fifo))
    emu = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        path = emu.stdout.readline().strip().split(": ", 1)[1]
        b = MoteusBackend(MoteusConfig(path=path, maximum_torque=20.0, reply_timeout=args.reply_timeout,
                                       watchdog_timeout=max(0.05, 2 * args.reply_timeout)))
        b.reset()
        b.round_trips.clear()
        h = 1.0 / args.rate
        n = int(round(args.duration * args.rate))
        overruns = 0
        t0 = time.monotonic()
        done = 0
        for k in range(n):
            if b.step(Command(0.5, 0.5)).fault is not None:
                break   # the figures are those of the steps before the fault
            done = k + 1
            deadline = t0 + (k + 1) * h
            now = time.monotonic()
            if now > deadline:
                overruns += 1
            else:
                time.sleep(deadline - now)
        wall = time.monotonic() - t0
        fault = b.fault
        rt = sorted(list(b.round_trips)[:done])
        missed = list(b.missed)
        b.close()
    finally:
        emu.send_signal(signal.SIGINT)
        _, err = emu.communicate(timeout=20)
    q = lambda p: rt[min(len(rt) - 1, int(math.ceil(p * len(rt))) - 1)] * 1e3   # noqa: E731
    result = {"rate_hz": args.rate, "steps": done, "steps_asked": n, "fault_after_s": wall if fault else None,
              "latency_s": args.latency, "jitter_s": args.jitter, "loss": args.loss,
              "rtt_median_ms": statistics.median(rt) * 1e3, "rtt_p99_ms": q(0.99), "rtt_max_ms": rt[-1] * 1e3,
              "overruns": overruns, "periods_per_wall_clock": done / (wall * args.rate), "missed": missed,
              "fault": fault, "fifo": args.fifo, "load": os.getloadavg()[0], "emulator": err.strip().splitlines()[-1]}
    print(json.dumps(result, indent=1))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=1)
    return 1 if fault else 0


if __name__ == "__main__":
    sys.exit(main())
