"""The mathematics of mwip_ros: plain Python over floats and numpy, no ROS, no file I/O (numba's cache aside).

Its rooms, each a concern, the lower ones first (a room imports only the rooms above it in this table):

========================  ==========================================================
:mod:`.plants`            the robot: its model (eq. 1-7), drive, sensors, the RK4 and MuJoCo plants, its markers
:mod:`.control`           what decides the command: DSC (eq. 16-28), the observer (eq. 8-15), LQR, Theorem 2, the
                          motion references, the yaw loop, the driver's state machine
:mod:`.laws`              the control laws' registry: dsc, lqr, smc, mpc, their _ndo variants, plug-ins
                          (``$MWIP_ROS_LAWS``)
:mod:`.estimators`        the state estimators from the raw sensors: complementary, kalman
:mod:`.identification`    identification from a log: the body, the raw sensors, the drive; the excitation
:mod:`.closed_loop`       one period's stages, the offline loop, the trajectory table, the metrics of a run
:mod:`.mobile_base`       the robot on the ground: odometry, the path of a run, the URDF and its frames
:mod:`.kernels`           many scenarios at once: the batch loop over numpy arrays and compiled by numba, its cache,
                          its SIMD lanes, the offline tools' memory budget
========================  ==========================================================

docs/theory.md has the equations; docs/architecture.md the map of the rooms and how the nodes use them.
"""
