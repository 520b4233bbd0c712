"""The mathematics of mwip_ros: plain Python over floats and numpy, no ROS, no file I/O (numba's cache aside).

========================  ==========================================================
:mod:`.model`             the state, rigid-body terms, true dynamics, lumped disturbance (eq. 1-7, 16-18)
:mod:`.plant`             the true plant stepped with RK4, D_w per period
:mod:`.observer`          the nonlinear disturbance observer (eq. 12-15), discrete form
:mod:`.controller`        DSC and DSCNDO (eq. 19-28), filter stepped exactly
:mod:`.lqr`               the LQR baseline: linearization, zero-order hold, Riccati, K
:mod:`.laws`              the control laws' registry: dsc, dscndo, lqr, lqr_ndo, plug-ins (``$MWIP_ROS_LAWS``)
:mod:`.theorem`           Theorem 2 (eq. 34-35), controller and observer halves
:mod:`.trajectory`        the trajectory table every source builds the same way
:mod:`.sim`               the closed loop, offline
:mod:`.metrics`           the metrics of a run
:mod:`.batch`             many scenarios at once: the closed loop over numpy arrays
:mod:`.compiled`          the plant's RK4 period for many scenarios: the same function compiled by numba
:mod:`.budget`            the offline tools' memory budget, and what a run costs, estimated before allocating
========================  ==========================================================

docs/theory.md has the equations; docs/architecture.md how the nodes use these modules.
"""
