"""A cmd_vel flood, as a process of its own (test/nodes/test_motion_flood.py, scripts/bench_cmd_vel_flood.py, by hand).

    python test/cmd_vel_flooder.py RATE DURATION [STATES] [--ros-args ...]

publishes RATE geometry_msgs/Twist a second on ``cmd_vel`` for DURATION seconds of wall time, starting once it heard
STATES (default 100) ``joint_states`` (the loop runs): in turn a valid command (linear.x = 0.3 m/s) and a NaN one the
controller must reject.  Prints ``flooded N in S s`` and exits 0.  Bursts every 5 ms; RATE 0: as fast as it can.
"""
import sys
import time

from flooder import await_loop, flood   # the same wait for the loop and the same bursts


def main(argv) -> int:
    args = argv[1:argv.index("--ros-args")] if "--ros-args" in argv else argv[1:]
    rate, duration = float(args[0]), float(args[1])
    states = int(args[2]) if len(args) > 2 else 100
    import rclpy
    from geometry_msgs.msg import Twist

    from mwip_ros.msgs import layouts as L
    rclpy.init()
    node = rclpy.create_node("cmd_vel_flooder")
    end = time.monotonic() + 120
    await_loop(node, states, end)
    pub = node.create_publisher(Twist, "cmd_vel", 10)
    start = time.monotonic()
    sent = flood((pub,), ((L.encode_twist(0.3, 0.0), L.encode_twist(float("nan"), 0.0)),), rate, duration, end)
    print(f"flooded {sent} in {time.monotonic() - start:.2f} s", flush=True)
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
