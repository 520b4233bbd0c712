#!/usr/bin/env python3
"""The DDS floor for ``scripts/bench.sh``: a two-process ping-pong of std_msgs/Float64.

    python scripts/bench_pingpong.py pong [--typed]                       # echo until SIGINT
    python scripts/bench_pingpong.py ping [--typed] --count N [--json F]  # N timed round trips

Both processes are built like the mwip_ros nodes: ``run_node`` (the same executor,
EventsExecutor unless MWIP_EXECUTOR=single, driven by the same ``spin_once`` loop),
reliable, KEEP_LAST 1, volatile QoS, and like the nodes they publish serialized
messages and take them with ``raw=True`` subscriptions (``--typed``: rclpy message
objects instead, to show what rclpy's conversion costs).  ``ping`` sends the next
message only when the previous one came back, so round trips/s is the most a strictly
sequential exchange of messages between two Python processes reaches on this machine.
"""
from __future__ import annotations

import argparse
import json
import sys
import time

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Float64

from mwip_ros.msgs import cdr
from mwip_ros.nodes.runtime.process import EXIT_ERROR, GracefulNodeMixin, run_node

QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                 durability=DurabilityPolicy.VOLATILE)
WARMUP = 200          # round trips before the clock starts
MATCH_TIMEOUT_S = 30.0
RESEND_NS = 500_000_000  # a round trip takes ~0.2 ms; one not back after 0.5 s was lost at start-up


class Pong(Node, GracefulNodeMixin):
    def __init__(self, typed: bool, context=None, argv=()):
        super().__init__("bench_pong", context=context)
        self.pub = self.create_publisher(Float64, "bench_pong", QOS)
        self.create_subscription(Float64, "bench_ping", self.pub.publish, QOS, raw=not typed)


class Ping(Node, GracefulNodeMixin):
    def __init__(self, typed: bool, count: int, json_path: str, context=None, argv=()):
        super().__init__("bench_ping", context=context)
        self.typed, self.count, self.json_path = typed, count, json_path
        self.pub = self.create_publisher(Float64, "bench_ping", QOS)
        self.sub = self.create_subscription(Float64, "bench_pong", self._on_pong, QOS, raw=not typed)
        self.msg = Float64()
        self.i = -1
        self.sent_ns = 0
        self.rtt_ns = [0] * count
        self.t0 = self.t1 = None
        self.started_wait = time.monotonic()

    def _send(self) -> None:
        self.i += 1
        self.sent_ns = time.perf_counter_ns()
        if self.typed:
            self.msg.data = float(self.i)
            self.pub.publish(self.msg)
        else:
            self.pub.publish(cdr.encode_float64(float(self.i)))

    def _on_pong(self, msg) -> None:
        now = time.perf_counter_ns()
        if (msg.data if self.typed else cdr.decode_float64(msg)) != float(self.i):
            return  # not the answer to the message in flight
        k = self.i - WARMUP        # the clock starts at the answer to message WARMUP (k = 0) ...
        if k == 0:
            self.t0 = now
        elif k > 0:
            self.rtt_ns[k - 1] = now - self.sent_ns
        if k == self.count:        # ... and stops at the answer to message WARMUP + count
            self.t1 = now
            self.finish()
            return
        self._send()

    def spin_step(self, executor) -> None:
        if self.i >= 0 and not self.done and time.perf_counter_ns() - self.sent_ns > RESEND_NS:
            self.i -= 1
            self._send()  # lost before both directions had matched (volatile QoS): send it again
        if self.i < 0:
            if self.pub.get_subscription_count() >= 1 and self.sub.get_publisher_count() >= 1:
                time.sleep(0.2)  # let both directions finish matching
                self._send()
            elif time.monotonic() - self.started_wait > MATCH_TIMEOUT_S:
                self.get_logger().error("no pong process matched")
                self.exit_code, self.done = EXIT_ERROR, True
                return
        executor.spin_once(timeout_sec=0.05)

    def on_shutdown(self) -> None:
        if self.t1 is None:
            return
        seconds = (self.t1 - self.t0) * 1e-9
        rtt = sorted(self.rtt_ns)
        result = {"round_trips": self.count, "seconds": seconds, "round_trips_per_s": self.count / seconds,
                  "rtt_us_p50": rtt[len(rtt) // 2] / 1e3, "rtt_us_p99": rtt[int(len(rtt) * 0.99)] / 1e3}
        print(json.dumps(result), flush=True)
        if self.json_path:
            with open(self.json_path, "w") as f:
                json.dump(result, f)


def main(argv=None) -> int:
    argv = list(sys.argv if argv is None else argv)
    ros_at = argv.index("--ros-args") if "--ros-args" in argv else len(argv)
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("role", choices=("ping", "pong"))
    ap.add_argument("--count", type=int, default=10000, help="timed round trips (ping; default 10000)")
    ap.add_argument("--json", default="", help="also write ping's result to this JSON file")
    ap.add_argument("--typed", action="store_true", help="rclpy message objects instead of serialized messages "
                                                         "(both processes must agree)")
    args = ap.parse_args(argv[1:ros_at])
    argv = argv[:1] + argv[ros_at:]   # run_node takes ROS arguments only (ours are parsed above)
    if args.count < 2:
        ap.error("--count must be at least 2")
    if args.role == "pong":
        return run_node(lambda context, argv: Pong(args.typed, context=context, argv=argv), argv)
    return run_node(lambda context, argv: Ping(args.typed, args.count, args.json, context=context, argv=argv), argv)


if __name__ == "__main__":
    sys.exit(main())
