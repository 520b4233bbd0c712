"""A flood of malformed raw-sensor messages, as a process of its own (test/nodes/test_flood.py, and by hand).

    python test/flooder.py RATE DURATION [STATES] [--ros-args ...]

publishes RATE messages a second on each of ``imu/data_raw`` and ``wheel_encoder`` for DURATION seconds of wall time,
starting once it heard STATES (default 100) ``joint_states`` (the loop runs), every one of which the state estimator
must reject: a non-finite reading, bytes cut short, a wrong frame_id, a wrong joint, a stamp 1,000 s ahead. Prints
``flooded N`` (the messages sent) and exits 0. Bursts every 5 ms; RATE 0: as fast as it can.
"""
import math
import sys
import time


def messages():
    from mwip_ros.msgs import cdr
    from mwip_ros.msgs import layouts as L
    g = 9.81
    imu = [L.encode_imu(5_000_000, math.nan, 0.0, g),
           L.encode_imu(5_000_000, 0.0, 0.0, g)[:-40],
           cdr.ImuEncoder("base_link")(5_000_000, (0.0,) * 4, (-1.0,) + (0.0,) * 8, (0.0,) * 3, (0.0,) * 9,
                                       (0.0, 0.0, g), (0.0,) * 9),
           L.encode_imu(1_000 * 10 ** 9, 0.0, 0.0, g)]
    enc = [L.encode_encoder(5_000_000, math.inf, 0.0, 0.0),
           L.encode_encoder(5_000_000, 0.0, 0.0, 0.0)[:-4],
           cdr.JointStateEncoder(("left",))(5_000_000, (0.0,), (0.0,), (0.0,)),
           L.encode_encoder(1_000 * 10 ** 9, 0.0, 0.0, 0.0)]
    return imu, enc


def await_loop(node, states: int, end: float) -> None:
    """Spin ``node`` until it has heard ``states`` joint_states (the loop runs), or until ``end`` (monotonic s).  It
    first waits to see the joint_states publisher and says so (``flooder: listening to joint_states``): a test starts
    the plant only then, since a short run can end before a late discovery would match this reader."""
    import rclpy
    from sensor_msgs.msg import JointState

    from mwip_ros.msgs.qos import REALTIME_INPUT_QOS
    heard = []
    node.create_subscription(JointState, "joint_states", lambda data: heard.append(1), REALTIME_INPUT_QOS, raw=True)
    while node.count_publishers("joint_states") < 1 and time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.05)
    print("flooder: listening to joint_states", flush=True)
    while len(heard) < states and time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.05)


def flood(pubs, streams, rate: float, duration: float, end: float) -> int:
    """Once every publisher of ``pubs`` is matched (or at ``end``), publish ``rate`` messages a second on each for
    ``duration`` s of wall time, cycling through its stream of ``streams``, in bursts every 5 ms (``rate`` 0: as
    fast as it can); the messages sent, all publishers together."""
    while min(p.get_subscription_count() for p in pubs) < 1 and time.monotonic() < end:
        time.sleep(0.01)
    sent, start, burst = 0, time.monotonic(), 0.005
    per_burst = max(1, round(rate * burst)) if rate > 0 else 50
    while time.monotonic() - start < duration:
        t0 = time.monotonic()
        for i in range(per_burst):
            for pub, stream in zip(pubs, streams):
                pub.publish(stream[(sent + i) % len(stream)])
        sent += per_burst
        if rate > 0:
            time.sleep(max(0.0, burst - (time.monotonic() - t0)))
    return len(pubs) * sent


def main(argv) -> int:
    args = argv[1:argv.index("--ros-args")] if "--ros-args" in argv else argv[1:]
    rate, duration = float(args[0]), float(args[1])
    states = int(args[2]) if len(args) > 2 else 100
    import rclpy
    from sensor_msgs.msg import Imu, JointState

    from mwip_ros.msgs.qos import REALTIME_QOS
    rclpy.init()
    node = rclpy.create_node("flooder")
    end = time.monotonic() + 120
    await_loop(node, states, end)
    pubs = (node.create_publisher(Imu, "imu/data_raw", REALTIME_QOS),   # now: the stream started alone
            node.create_publisher(JointState, "wheel_encoder", REALTIME_QOS))
    start = time.monotonic()
    sent = flood(pubs, messages(), rate, duration, end)
    print(f"flooded {sent} in {time.monotonic() - start:.2f} s", flush=True)
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
