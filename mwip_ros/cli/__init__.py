"""Command-line tools that need no ROS graph.

====================  ==============================================================
:mod:`.sim`           ``mwip_sim``: the offline closed loop, metrics, CSV, Fig. 3 plot
:mod:`.theorem`       ``mwip_theorem``: Theorem 2's a1..a5 for a parameter file
:mod:`.report`        ``mwip_report``: figures and metrics from bags or CSVs
:mod:`.bag_repair`    ``mwip_bag_repair``: recover a bag cut short
:mod:`.plotting`      the figures
====================  ==============================================================
"""
