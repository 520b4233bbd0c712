"""``python -m mwip_ros.nodes NODE [--ros-args ...]``: a node started as its console script starts it
(:mod:`mwip_ros.nodes.runtime.entry`: the malloc arena limit before rclpy is imported)."""
import sys

from mwip_ros.nodes.runtime.entry import main

if __name__ == "__main__":
    sys.exit(main())
