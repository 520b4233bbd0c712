"""The tool nodes: outside the loop, they record, replay, re-simulate and show it.

==========================  ==================================================================
:mod:`.mcap_recorder`       records the graph into a rosbag2 MCAP bag (split by size and duration)
:mod:`.bag_replay`          replays a bag (:mod:`.replay`) or re-simulates it (:mod:`.resim`)
:mod:`.comparison`          re-simulated outputs against recorded ones
:mod:`.tap`                 raw subscriptions that pass bytes on unread (recorder, live view)
:mod:`.foxglove_server`     the Foxglove live view: the node
:mod:`.foxglove_connections`  its connection management around the SDK
:mod:`.foxglove_relay`      its port: both WebSocket subprotocols in front of the SDK
:mod:`.robot_markers`       the robot as a MarkerArray, for Foxglove or RViz
==========================  ==================================================================
"""
