"""What every node runs on: process start, parameters, input guards, lockstep, diagnostics, rclpy internals.

==========================  ==================================================================
:mod:`.entry`               the console scripts' entry points: the malloc arena limit, then the node's ``main``
:mod:`.process`             process plumbing, exit codes, ``run_node``, rejected-message counts
:mod:`.params`              declares a node's parameters from the schema, validates updates
:mod:`.guards`              checks of incoming messages: stamps, publishers, rejects (plain Python)
:mod:`.state_input`         a node's state subscription with its guards
:mod:`.lockstep`            the one lockstep driver (plant_sim and resim)
:mod:`.schedule`            the realtime loop's absolute deadlines and timing (plain Python)
:mod:`.diagnostics`         ``/diagnostics`` for every node
:mod:`.rclpy_compat`        everything that reaches into rclpy's internals, for the rclpy it was written for
:mod:`.memtrace`            a debugging aid (``MWIP_MEMTRACE``): RSS, Python heap and glibc heap over a long run
==========================  ==================================================================
"""
