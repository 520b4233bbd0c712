"""mwip_ros: DSC with a nonlinear disturbance observer (DSCNDO) for a mobile wheeled inverted pendulum.

===============  =================================================================
:mod:`.core`     the mathematics (no ROS, no file I/O)
:mod:`.params`   the parameter schema and parameter files
:mod:`.yamlio`   the one YAML reader (bounded: size, no aliases, nodes, depth), for params, specs and bags
:mod:`.msgs`     the message layer (CDR codec, layouts, stamps, topics, QoS)
:mod:`.bag`      rosbag2 MCAP bags: write, read, repair
:mod:`.runs`     trajectories on disk (CSV, a bag rebuilt into a trajectory)
:mod:`.nodes`    the ROS 2 nodes
:mod:`.cli`      command-line tools without ROS
===============  =================================================================

docs/theory.md has the mathematics, docs/architecture.md the layers.
"""
