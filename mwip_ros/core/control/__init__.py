"""What decides the command: the controller (DSC, eq. 16-28), the disturbance observer (eq. 8-15), the LQR design,
Theorem 2, the motion references, the yaw loop and the driver's state machine.

The laws (:mod:`mwip_ros.core.laws`) are composed from these pieces; they stand on :mod:`mwip_ros.core.plants` only.
"""
