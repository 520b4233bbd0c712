"""The ROS 2 nodes, in three rooms by what they are.

======================  ====================================================================
:mod:`.loop`            the closed loop's nodes: plant_sim (and its runners), state_estimator,
                        disturbance_observer, dscndo_controller
:mod:`.tools`           the tool nodes: mcap_recorder, bag_replay (replay, resim), foxglove_server
                        (its connections and relay), robot_markers, and the tap they share
:mod:`.runtime`         what every node runs on: entry (the console scripts), process (``run_node``,
                        exit codes), params, guards, state_input, lockstep, diagnostics, rclpy_compat
======================  ====================================================================

A node parses parameters, subscribes, calls the core (:mod:`mwip_ros.core`) and publishes
through the message layer (:mod:`mwip_ros.msgs`); docs/architecture.md follows one state
sample through them.  Importing this package (or any node module) changes nothing in the process:
what a node process needs is done by :mod:`.runtime.entry` and ``run_node``, explicitly.
"""
