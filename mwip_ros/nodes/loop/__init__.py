"""The nodes of the closed loop, in the order of a period (``core.closed_loop.loop.STAGES``).

==========================  ==================================================================
:mod:`.plant_sim`           the true robot (sensors, drive, safety, plant): lockstep or realtime
:mod:`.plant_runners`       its two runners, ``LockstepRunner`` and ``RealtimeRunner``
:mod:`.wheel_driver`        a robot's side instead of the plant: a backend's devices read and written (docs/hardware.md)
:mod:`.state_estimator`     raw IMU and encoder samples into the state (docs/theory.md 6.4)
:mod:`.disturbance_observer`  the NDO (eq. 12-15)
:mod:`.dscndo_controller`   the law: DSC / DSCNDO (eq. 19-28) or any registered law
==========================  ==================================================================
"""
