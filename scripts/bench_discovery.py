#!/usr/bin/env python3
"""How long a newcomer takes to find a running node, under each discovery set-up (docs/graph.md, Discovery).

Each trial starts one *idle* participant (a node with a subscription and a Trigger service, as a running
graph's node is), waits until it has been up ``--settle`` seconds, then starts ``--newcomers`` processes at
the same moment (as a script starts the observer, the controller and the plant). Each newcomer measures, from
the end of its ``rclpy.init`` (its participant exists), how long until

- ``match``: its publisher has matched the idle node's subscription (it found the node), and
- ``reply``: the idle node answered its first service request (the request sent again every 0.5 s until one
  answer comes, as ``mwip_ros.nodes.runtime.services`` does): what ``mwip_ctl`` waits for.

Variants (``--variants``; each is run in turns with the others, so a machine's load falls on all alike):

- ``default``: Fast DDS as it comes (participants announce themselves every 3 s);
- ``product``: the profile mwip_ros ships (``mwip_ros.nodes.runtime.discovery``), as every node applies it;
- ``lease=S``: a profile whose participants announce every S seconds (nothing else changed);
- ``server``: a Fast DDS discovery server (``fastdds discovery``) on loopback, every participant its client;
- ``profile=FILE``: a Fast DDS XML profile of your own (the package's left off);
- ``async``: the package's profile with ``RMW_FASTRTPS_PUBLICATION_MODE=ASYNCHRONOUS``.

``--busy N`` runs N busy-loop processes beside the trials (the issue's load: two). Prints one table: per variant
the median, 90th percentile and largest time of each measure, and how many newcomers took over 1 s.

``--stall N`` measures what a newcomer that stops in the middle of its discovery (a Ctrl-Z, a process starved of
CPU) costs a running realtime graph: N newcomers join the plant's graph one after another, each stopped 0.3 + 0.1 i s
after its start, and the plant's line on its wake periods is printed (the largest period is the loop's stall).

``--ctl N`` measures instead what a user waits for: a realtime graph (observer, controller, plant) runs under each
variant, and ``mwip_ctl param get dscndo_controller k1`` is timed N times, whole (its Python start included).

    python scripts/bench_discovery.py --trials 20 --busy 2
    python scripts/bench_discovery.py --ctl 6 --busy 2 --variants default,product
    python scripts/bench_discovery.py --stall 12 --variants product
"""
from __future__ import annotations

import argparse
import contextlib
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Dict, List, Optional

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

PROFILE = """<?xml version="1.0" encoding="UTF-8"?>
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <participant profile_name="bench_lease" is_default_profile="true">
    <rtps>
      <builtin>
        <discovery_config>
          <leaseAnnouncement><sec>{sec}</sec><nanosec>{nanosec}</nanosec></leaseAnnouncement>
        </discovery_config>
      </builtin>
    </rtps>
  </participant>
</profiles>
"""


# ---------------------------------------------------------------------------------------------------- the roles
def _init(name: str):
    import rclpy
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node(name, context=ctx)
    return rclpy, ctx, node


def role_idle() -> int:
    """A running node: a subscription on ``probe`` and a Trigger service ``probe_srv``; runs until killed."""
    from std_msgs.msg import Float64
    from std_srvs.srv import Trigger
    rclpy, ctx, node = _init("bench_idle")

    def answer(_req, resp):
        resp.success = True
        return resp
    node.create_subscription(Float64, "probe", lambda _m: None, 10)
    node.create_service(Trigger, "probe_srv", answer)
    print("READY", flush=True)
    from rclpy.executors import SingleThreadedExecutor
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    while ctx.ok():
        ex.spin_once(timeout_sec=0.1)
    return 0


def role_new(limit: float) -> int:
    """A newcomer: prints ``match S`` and ``reply S`` (seconds from its participant's creation; -1: not within
    ``limit``)."""
    from std_msgs.msg import Float64
    from std_srvs.srv import Trigger
    rclpy, ctx, node = _init(f"bench_new_{os.getpid()}")
    t0 = time.monotonic()
    pub = node.create_publisher(Float64, "probe", 10)
    client = node.create_client(Trigger, "probe_srv")
    from rclpy.executors import SingleThreadedExecutor
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    match = reply = None
    future, sent = None, -1.0
    while time.monotonic() - t0 < limit and (match is None or reply is None):
        ex.spin_once(timeout_sec=0.002)
        now = time.monotonic()
        if match is None and pub.get_subscription_count() >= 1:
            match = now - t0
        if reply is None:
            if future is not None and future.done():
                reply = now - t0
            elif client.service_is_ready() and now - sent >= 0.5:
                future, sent = client.call_async(Trigger.Request()), now
    print(f"match {match if match is not None else -1:.4f}", flush=True)
    print(f"reply {reply if reply is not None else -1:.4f}", flush=True)
    node.destroy_node()
    rclpy.shutdown(context=ctx)
    return 0


# ------------------------------------------------------------------------------------------------ the orchestra
def variant_env(variant: str, base: Dict[str, str], tmp: Path) -> Dict[str, str]:
    env = dict(base)
    for key in ("FASTRTPS_DEFAULT_PROFILES_FILE", "ROS_DISCOVERY_SERVER", "MWIP_DISCOVERY"):
        env.pop(key, None)
    if variant == "default":
        env["MWIP_DISCOVERY"] = "off"
    elif variant == "product":
        from mwip_ros.nodes.runtime import discovery
        discovery.apply(env)
    elif variant.startswith("lease="):
        seconds = float(variant.split("=", 1)[1])
        path = tmp / f"lease_{seconds:g}.xml"
        sec = int(seconds)
        path.write_text(PROFILE.format(sec=sec, nanosec=round((seconds - sec) * 1e9)))
        env["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(path)
        env["MWIP_DISCOVERY"] = "off"
    elif variant.startswith("profile="):
        env["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(Path(variant.split("=", 1)[1]).resolve())
        env["MWIP_DISCOVERY"] = "off"
    elif variant == "async":
        from mwip_ros.nodes.runtime import discovery
        discovery.apply(env)
        env["RMW_FASTRTPS_PUBLICATION_MODE"] = "ASYNCHRONOUS"
    elif variant == "server":
        env["ROS_DISCOVERY_SERVER"] = "127.0.0.1:11888"
        env["MWIP_DISCOVERY"] = "off"
    else:
        raise SystemExit(f"bench_discovery: unknown variant {variant!r}")
    return env


def one_trial(env: Dict[str, str], newcomers: int, settle: float, limit: float) -> List[Dict[str, float]]:
    me = [sys.executable, str(Path(__file__).resolve())]
    idle = subprocess.Popen(me + ["--role", "idle"], env=env, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                            text=True)
    try:
        line = idle.stdout.readline()
        if not line.startswith("READY"):
            raise SystemExit("bench_discovery: the idle node did not start")
        time.sleep(settle)   # the idle node past its own initial announcements: a running graph's node
        procs = [subprocess.Popen(me + ["--role", "new", "--limit", str(limit)], env=env, stdout=subprocess.PIPE,
                                  stderr=subprocess.DEVNULL, text=True) for _ in range(newcomers)]
        out = []
        for p in procs:
            text, _ = p.communicate(timeout=limit + 30)
            got = dict(ln.split() for ln in text.splitlines() if ln.startswith(("match", "reply")))
            out.append({k: float(v) for k, v in got.items()})
        return out
    finally:
        idle.terminate()
        try:
            idle.wait(timeout=10)
        except subprocess.TimeoutExpired:
            idle.kill()
            idle.wait()


@contextlib.contextmanager
def realtime_graph(env: Dict[str, str], duration: float):
    """(the Graph, its plant) of the realtime loop (observer, controller, plant for ``duration`` s, 0: until
    stopped) started in ``env`` and running; every process ended by PID after."""
    sys.path.insert(0, str(REPO / "test"))
    from graphproc import Graph
    with tempfile.TemporaryDirectory() as tmp, Graph(Path(tmp)) as g:
        g.env = dict(env)
        for node in ("disturbance_observer", "dscndo_controller"):
            g.start(node, "-p", "mode:=realtime")
        plant = g.start("plant_sim", "-p", "mode:=realtime", "-p", f"duration_s:={duration:.1f}")
        if not plant.wait_for_output("starting realtime run", 60):
            raise SystemExit(f"bench_discovery: the graph did not start:\n{plant.output()[-2000:]}")
        yield g, plant


def ctl_calls(env: Dict[str, str], calls: int) -> List[float]:
    """Seconds each of ``calls`` runs of ``mwip_ctl param get dscndo_controller k1`` takes against a realtime graph
    started in ``env`` (the graph ended by PID after)."""
    with realtime_graph(env, 0.0) as (g, plant):
        took = []
        for _ in range(calls):
            t0 = time.monotonic()
            r = subprocess.run([sys.executable, "-m", "mwip_ros.cli.ctl", "param", "get", "dscndo_controller", "k1"],
                               env=env, capture_output=True, text=True, timeout=60)
            took.append(time.monotonic() - t0)
            if r.returncode != 0:
                raise SystemExit(f"bench_discovery: mwip_ctl failed: {r.stderr.strip()}")
        return took


STALLED_NEWCOMER = """
import time, rclpy
from mwip_ros.nodes.runtime import discovery
discovery.apply()
rclpy.init()
node = rclpy.create_node("newcomer")
time.sleep(120)
"""


def stalled_newcomers(env: Dict[str, str], newcomers: int, duration: float = 20.0) -> str:
    """The realtime graph's plant (started in ``env``, ``duration`` s) while ``newcomers`` processes join it one after
    another, each stopped (SIGSTOP) 0.3 + 0.1 i s after its start, in the middle of its discovery, as a terminal's
    Ctrl-Z stops a ``ros2 topic echo``: the plant's own line on its wake periods (their largest is a stall of the
    loop), and whether it stayed upright."""
    stopped = []
    with realtime_graph(env, duration) as (g, plant):
        try:
            time.sleep(1.0)
            for i in range(newcomers):
                p = subprocess.Popen([sys.executable, "-c", STALLED_NEWCOMER], env=g.env, stdout=subprocess.DEVNULL,
                                     stderr=subprocess.DEVNULL)
                stopped.append(p)
                time.sleep(0.3 + 0.1 * i)
                p.send_signal(signal.SIGSTOP)
            code = plant.wait(duration + 60)
        finally:
            for p in stopped:
                p.kill()
                p.wait()
        out = plant.output()
    line = next((ln for ln in reversed(out.splitlines()) if "periods due" in ln), "no realtime line")
    return f"exit {code} ({'upright' if code == 0 else 'not upright'}); " + line[line.find("realtime:"):]


def summary(values: List[float], limit: float) -> str:
    lost = sum(1 for v in values if v < 0)
    seen = sorted(v for v in values if v >= 0)
    if not seen:
        return f"none within {limit:g} s"
    p90 = seen[min(len(seen) - 1, int(round(0.9 * (len(seen) - 1))))]
    over = sum(1 for v in seen if v > 1.0) + lost
    return (f"{statistics.median(seen):.3f} / {p90:.3f} / {max(seen):.3f} s, over 1 s: {over}/{len(values)}"
            + (f" ({lost} not within {limit:g} s)" if lost else ""))


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 epilog="see the module docstring: python -m pydoc scripts/bench_discovery.py")
    ap.add_argument("--role", choices=("idle", "new"), help=argparse.SUPPRESS)
    ap.add_argument("--limit", type=float, default=8.0, help="a newcomer gives up after this long [s] (default 8)")
    ap.add_argument("--trials", type=int, default=10, help="trials per variant (default 10)")
    ap.add_argument("--newcomers", type=int, default=3, help="newcomers started together per trial (default 3)")
    ap.add_argument("--settle", type=float, default=1.5,
                    help="the idle node runs this long before the newcomers start [s] (default 1.5)")
    ap.add_argument("--busy", type=int, default=0, help="busy-loop processes beside the trials (default 0)")
    ap.add_argument("--ctl", type=int, default=0, metavar="N",
                    help="time N mwip_ctl param get calls against a running graph per variant instead")
    ap.add_argument("--stall", type=int, default=0, metavar="N",
                    help="a realtime graph per variant, N newcomers joining it stopped mid-start: the plant's stall")
    ap.add_argument("--variants", default="default,product,server",
                    help="comma-separated: default, product, lease=S, server, profile=FILE, async "
                         "(default: default,product,server)")
    args = ap.parse_args(argv)
    if args.role == "idle":
        return role_idle()
    if args.role == "new":
        return role_new(args.limit)

    base = dict(os.environ)
    base["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    if "ROS_DOMAIN_ID" not in base:
        sys.path.insert(0, str(REPO / "test"))
        from graphproc import fresh_domain_id   # the locked domains the project's runs use
        base["ROS_DOMAIN_ID"] = str(fresh_domain_id())
    variants = [v.strip() for v in args.variants.split(",") if v.strip()]
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(args.busy)]
    server = None
    results: Dict[str, Dict[str, List[float]]] = {v: {"match": [], "reply": []} for v in variants}
    try:
        with tempfile.TemporaryDirectory() as tmp:
            envs = {v: variant_env(v, base, Path(tmp)) for v in variants}
            if "server" in variants:
                server = subprocess.Popen(["fastdds", "discovery", "-i", "0", "-l", "127.0.0.1", "-p", "11888"],
                                          env=base, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                          start_new_session=True)   # the fastdds wrapper's server child too
                time.sleep(1.0)
            if args.stall:
                for v in variants:
                    print(f"| {v} | {args.stall} stopped newcomers: {stalled_newcomers(envs[v], args.stall)} |",
                          flush=True)
                return 0
            if args.ctl:
                for v in variants:
                    took = ctl_calls(envs[v], args.ctl)
                    print(f"| {v} | mwip_ctl param get, {args.ctl} calls: median {statistics.median(took):.2f} s "
                          f"({', '.join(f'{t:.2f}' for t in took)}) |", flush=True)
                return 0
            for trial in range(args.trials):
                for v in variants:
                    for got in one_trial(envs[v], args.newcomers, args.settle, args.limit):
                        for key in ("match", "reply"):
                            results[v][key].append(got.get(key, -1.0))
                print(f"bench_discovery: trial {trial + 1}/{args.trials} done", file=sys.stderr, flush=True)
    finally:
        for p in busy:
            p.kill()
            p.wait()
        if server is not None:   # the wrapper and the server it started: its whole session
            os.killpg(server.pid, signal.SIGKILL)
            server.wait()
    print(f"\n{args.trials} trials x {args.newcomers} newcomers, {args.busy} busy process(es) beside; "
          "median / 90th percentile / largest")
    print("| variant | match (found the node) | first service reply |")
    print("|---|---|---|")
    for v in variants:
        print(f"| {v} | {summary(results[v]['match'], args.limit)} | {summary(results[v]['reply'], args.limit)} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
