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
:mod:`.guards`             stamps, rejected-message counts, a second publisher (plain Python)
:mod:`.state_input`        ``joint_states`` as the observer and the controller take it
:mod:`.rclpy_compat`       everything that reaches into rclpy's internals, for the rclpy it was written for
:mod:`.entry`              the console scripts' entry points: the malloc arena limit, then the node's ``main``
========================  ==============================================================

A node parses parameters, subscribes, calls the core (:mod:`mwip_ros.core`) and publishes
through the message layer (:mod:`mwip_ros.msgs`); docs/architecture.md follows one state
sample through them.  Importing this package (or any node module) changes nothing in the process:
what a node process needs is done by :mod:`.entry` and ``run_node``, explicitly.
"""
