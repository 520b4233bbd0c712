"""The robot as it is simulated and measured: its model (eq. 1-7), the drive, the sensors, the plants that step it.

Everything here describes the robot; nothing here decides a command.  The other rooms of :mod:`mwip_ros.core` stand
on this one (the controller and the observer use the *nominal* model's terms), and it imports none of them.
"""
