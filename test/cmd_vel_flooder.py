"""A cmd_vel flood, as a process of its own (test/nodes/test_motion_flood.py, scripts/bench_cmd_vel_flood.py, by hand).

    python test/cmd_vel_flooder.py RATE DURATION [STATES] [--ros-args ...]

publishes RATE geometry_msgs/Twist a second on ``cmd_vel`` for DURATION seconds of wall time, starting once it heard
STATES (default 100) ``joint_states`` (the loop runs): in turn a valid command (linear.x = 0.3 m/s) and a NaN one the
controller must reject.  Prints ``flooded N in S s`` and exits 0.  Bursts every 5 ms; RATE 0: as fast as it can.
"""
import sys
import time


def main(argv) -> int:
    args = argv[1:argv.index("--ros-args")] if "--ros-args" in argv else argv[1:]
    rate, duration = float(args[0]), float(args[1])
    states = int(args[2]) if len(args) > 2 else 100
    import rclpy
    from geometry_msgs.msg import Twist
    from sensor_msgs.msg import JointState

    from mwip_ros.msgs import layouts as L
    from mwip_ros.msgs.qos import REALTIME_INPUT_QOS
    rclpy.init()
    node = rclpy.create_node("cmd_vel_flooder")
    heard = []
    node.create_subscription(JointState, "joint_states", lambda data: heard.append(1), REALTIME_INPUT_QOS, raw=True)
    end = time.monotonic() + 120
    while len(heard) < states and time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.05)
    pub = node.create_publisher(Twist, "cmd_vel", 10)
    while pub.get_subscription_count() < 1 and time.monotonic() < end:
        time.sleep(0.01)
    msgs = (L.encode_twist(0.3, 0.0), L.encode_twist(float("nan"), 0.0))
    sent, start, burst = 0, time.monotonic(), 0.005
    per_burst = max(1, round(rate * burst)) if rate > 0 else 50
    while time.monotonic() - start < duration:
        t0 = time.monotonic()
        for i in range(per_burst):
            pub.publish(msgs[(sent + i) % 2])
        sent += per_burst
        if rate > 0:
            time.sleep(max(0.0, burst - (time.monotonic() - t0)))
    print(f"flooded {sent} in {time.monotonic() - start:.2f} s", flush=True)
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
