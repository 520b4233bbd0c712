"""The message layer: the only place that knows how the graph's messages look on the wire.

==================  ================================================================
:mod:`.cdr`         CDR encoding and decoding of the graph's message types, no rclpy
:mod:`.layouts`     what each topic carries (joint names, internals) and its checks
:mod:`.stamps`      integer nanoseconds <-> builtin_interfaces/Time
:mod:`.topics`      topic names and message types; importing a message class
:mod:`.qos`         the graph's QoS (imports rclpy)
:mod:`.errors`      ``MessageError``, ``CdrError``, ``BadMessage``
==================  ================================================================
"""
from .errors import BadMessage, CdrError, MessageError

__all__ = ["BadMessage", "CdrError", "MessageError"]
