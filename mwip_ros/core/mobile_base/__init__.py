"""The robot as a mobile base on the ground: wheel odometry (docs/theory.md 6.12), the path of a run against its
references, and the robot's URDF and frames for ``robot_description``.
"""
