"""A flood on the loop's side inputs, as a process of its own (test/nodes/test_hostile4_flood.py,
scripts/bench_input_flood.py, by hand).

    python test/side_flooder.py TOPICS DURATION [STATES] [--ros-args ...]

publishes as fast as it can, for DURATION seconds of wall time, on each of TOPICS (comma-separated, any of ``cmd_vel``,
``cmd_vel_bad``, ``cmd_vel_valid``, ``emergency_stop``, ``external_wrench``, ``driver_state``, ``disturbance_estimate``,
``joint_states``, ``disturbance_estimate_bad``, ``joint_states_bad``) in turn, starting once it heard STATES (default
100) ``joint_states`` (the loop runs). Each topic gets what a hostile publisher would send: cmd_vel a NaN Twist and a
valid one (0.3 m/s) in turn, emergency_stop false (released), external_wrench a zero wrench, cmd_vel_bad Twists with
NaN, inf and 1e300 in linear.x or angular.z (every one to be rejected), cmd_vel_valid valid Twists of +-0.3 m/s in turn
(both on ``cmd_vel``, beside a second publisher's 20 Hz stream of a valid command, 0.2 m/s: the operator's),
driver_state an ``enabled`` record, disturbance_estimate and joint_states stamps 1,000 s ahead (rejected), their
``_bad`` kinds NaN, inf and absurd values (dropped by the realtime nodes' content filters, layouts.STATE_FILTER /
ESTIMATE_FILTER). Prints ``flooded N in S s`` (the messages, all topics) and exits 0.
"""
import json
import sys
import time

from flooder import await_loop


def streams(topics):
    """[(message type, topic, [CDR bytes, ...])] of ``topics``."""
    from geometry_msgs.msg import Twist, Wrench, WrenchStamped
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Bool, String

    from mwip_ros.msgs import cdr
    from mwip_ros.msgs import layouts as L
    ahead = 1000 * 10 ** 9
    nan, inf = float("nan"), float("inf")
    bad = [L.encode_twist(vx, wz) for vx, wz in ((nan, 0.0), (inf, 0.0), (-inf, 0.0), (1e300, 0.0), (0.0, nan),
                                                 (0.0, inf), (0.0, -1e300), (nan, nan))]
    known = {
        "cmd_vel": lambda: (Twist, [L.encode_twist(float("nan"), 0.0), L.encode_twist(0.3, 0.0)]),
        "cmd_vel_bad": lambda: (Twist, bad),
        "cmd_vel_valid": lambda: (Twist, [L.encode_twist(0.3, 0.0), L.encode_twist(-0.3, 0.0)]),
        "emergency_stop": lambda: (Bool, [cdr.CDR_LE + b"\x00"]),
        "external_wrench": lambda: (Wrench, [L.encode_external_wrench(0.0, 0.0)]),
        "driver_state": lambda: (String, [cdr.encode_string(json.dumps({"state": "enabled"}))]),
        "disturbance_estimate": lambda: (WrenchStamped, [L.encode_wrench(ahead + i * 5_000_000, 0.0, 0.0)
                                                         for i in range(50)]),
        "joint_states": lambda: (JointState, [L.encode_state(ahead + i * 5_000_000, (0.0,) * 4, 0.0)
                                              for i in range(50)]),
        "disturbance_estimate_bad": lambda: (WrenchStamped, [L.encode_wrench(0, v, 0.0) for v in (nan, inf, 1e300)]
                                             + [L.encode_wrench(0, 0.0, v) for v in (nan, -inf, -1e300)]),
        "joint_states_bad": lambda: (JointState, [L.encode_state(0, tuple(v if j == i else 0.0 for j in range(4)), 0.0)
                                                  for i in range(4) for v in (nan, inf, 1e300)]),
    }
    return [(t_m[0], t.split("_bad")[0].split("_valid")[0], t_m[1]) for t, t_m in ((t, known[t]()) for t in topics)]


def main(argv) -> int:
    args = argv[1:argv.index("--ros-args")] if "--ros-args" in argv else argv[1:]
    topics, duration = args[0].split(","), float(args[1])
    states = int(args[2]) if len(args) > 2 else 100
    import rclpy
    rclpy.init()
    node = rclpy.create_node("side_flooder")
    end = time.monotonic() + 120
    await_loop(node, states, end)
    pubs = [(node.create_publisher(t, topic, 10), msgs) for t, topic, msgs in streams(topics)]
    steady = None   # the operator's 20 Hz valid commands beside a cmd_vel_bad / cmd_vel_valid flood
    if any(t in ("cmd_vel_bad", "cmd_vel_valid") for t in topics):
        from geometry_msgs.msg import Twist

        from mwip_ros.msgs import layouts as L
        steady = node.create_publisher(Twist, "cmd_vel", 10), L.encode_twist(0.2, 0.0)
    matched = time.monotonic() + 10.0
    while min(p.get_subscription_count() for p, _ in pubs) < 1 and time.monotonic() < matched:
        time.sleep(0.01)
    sent, steadies, start = 0, 0, time.monotonic()
    tick = start
    while (now := time.monotonic()) - start < duration:
        if steady is not None and now >= tick:
            steady[0].publish(steady[1])
            steadies += 1
            tick += 0.05
        for i in range(50):
            for pub, msgs in pubs:
                pub.publish(msgs[(sent + i) % len(msgs)])
        sent += 50
    print(f"flooded {sent * len(pubs)} in {time.monotonic() - start:.2f} s" +
          (f" (and {steadies} valid at 20 Hz)" if steady is not None else ""), flush=True)
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
