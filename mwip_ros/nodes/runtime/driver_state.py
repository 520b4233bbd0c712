"""The driver's transitions as the loop's robot side reports them (plant_sim, wheel_driver): one line in the log, one
JSON record on ``driver_state`` (docs/graph.md), kept for the run's summary."""
from __future__ import annotations

import json
from typing import List, Optional

from mwip_ros.core.control.safety import FAULT, Transition

__all__ = ["publish_transition"]


def publish_transition(node, pub, transitions: List[dict], tr: Optional[Transition], stamp_ns: int,
                       start: bool = False, **extra) -> None:
    """Log ``tr`` (one line: INFO at the start, ERROR for a fault, else WARN), append its record to ``transitions``
    (not at the start) and publish the record on ``pub`` (``std_msgs/String``, JSON); ``extra`` joins the record.
    Nothing for ``tr`` None."""
    from std_msgs.msg import String
    if tr is None:
        return
    record = {"state": tr.to_state, "from": tr.from_state or None, "reason": tr.reason, "detail": tr.detail,
              "t": round(tr.t, 9), "stamp_ns": stamp_ns, "text": tr.text(), **extra}
    if start:
        node.get_logger().info(f"driver: {tr.to_state} at the start ({tr.detail})")
    else:
        transitions.append(record)
        if tr.to_state == FAULT:   # (one call site per severity: rclpy's logger wants that)
            node.get_logger().error(f"driver: {tr.text()}")
        else:
            node.get_logger().warning(f"driver: {tr.text()}")
    pub.publish(String(data=json.dumps(record, allow_nan=False)))
