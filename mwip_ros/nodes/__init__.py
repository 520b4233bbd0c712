"""The ROS 2 nodes, one per file, and what they share.

========================  ==============================================================
:mod:`.plant_sim`          the true robot: lockstep or realtime
:mod:`.disturbance_observer`  the NDO
:mod:`.dscndo_controller`  DSC / DSCNDO
:mod:`.mcap_recorder`      records the graph into a rosbag2 MCAP bag
:mod:`.robot_markers`      the robot as a MarkerArray, for Foxglove or RViz
:mod:`.bag_replay`         replays a bag (:mod:`.replay`) or re-simulates it (:mod:`.resim`)
:mod:`.lockstep`           the one lockstep driver (plant_sim and resim)
:mod:`.params`             declares a node's parameters from the schema, validates updates
:mod:`.runtime`            process plumbing, exit codes, ``finish``, rejected-message counts
:mod:`.rclpy_compat`       what reaches into rclpy: parameter requests it cannot read are refused
========================  ==============================================================

A node parses parameters, subscribes, calls the core (:mod:`mwip_ros.core`) and publishes
through the message layer (:mod:`mwip_ros.msgs`); docs/architecture.md follows one state
sample through them.
"""
import ctypes as _ctypes
import os as _os

_M_ARENA_MAX = -8   # glibc's mallopt() parameter number for the arena limit


def _bound_malloc_arenas(arenas: int = 1) -> None:
    """Let every thread of a node allocate from one glibc malloc arena (unless ``MALLOC_ARENA_MAX`` is set).

    Under a flood of messages Fast DDS's receive threads and the executor allocate and free small
    buffers in turns; with an arena per thread (glibc's default, up to 8 per core) the arenas keep
    their fragments, and an observer's resident memory grew by about 5 MiB per 100,000 messages, for
    as long as the flood lasted.  With one arena it stays flat (``scripts/soak.py``, BENCHMARKS.md).
    glibc fixes the limit when a second thread first allocates, so this runs when the nodes package
    is imported, before numpy or rclpy start threads.  No effect on a C library without ``mallopt``.
    """
    if _os.environ.get("MALLOC_ARENA_MAX"):
        return
    try:
        _ctypes.CDLL(None).mallopt(_M_ARENA_MAX, arenas)
    except (OSError, AttributeError):  # pragma: no cover - not glibc
        pass


_bound_malloc_arenas()
