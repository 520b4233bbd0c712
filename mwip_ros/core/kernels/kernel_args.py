"""The batch kernel's arguments by name: :class:`LoopArgs`, the one call of :func:`.compiled.kernel_for`'s loop.

The compiled loop (:func:`.compiled._loop`) takes its 60 arguments positionally (numba compiles one signature of
plain arrays and numbers); :mod:`.batch` builds them as a :class:`LoopArgs` by keyword and calls
``kernel(*args)``.  The fields are the loop's parameters in its order (a test checks it), grouped here by meaning.
Per-scenario arrays have a row per scenario (n rows).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["LoopArgs"]


class LoopArgs(NamedTuple):
    # --- the periods of this call and the run's timing
    k0: int                  # first period of this call
    k1: int                  # one past its last
    n_steps: int             # the run's last period (duration / h)
    h: float                 # control period [s]
    substeps: int            # RK4 sub-steps per period
    first_w: int             # first period of the metrics window
    n_window: int            # periods in the window
    # --- the sensors and the actuator shared by every scenario (core.plants.sensing)
    counts: int              # encoder counts per revolution (0: none)
    delay: int               # measurement delay [periods]
    act_delay: int           # actuator delay [periods]
    observer_law: bool       # the law has an observer variant (core.laws.ndo)
    # --- each scenario's plant and law
    act: np.ndarray          # (n, 4) the actual plant's eq. (2) terms m11, m12, m22, G_b
    nom: np.ndarray          # (n, 4) the nominal model's
    D_b: np.ndarray          # (n,) body friction
    sins: np.ndarray         # (n, 6) tau_ext1 and tau_ext2: amplitude, omega, phase each
    shared: bool             # every scenario has sins' row 0 (the stage torques computed once, into T)
    limit: np.ndarray        # (n,) torque limit (0: none)
    fall: np.ndarray         # (n,) fall angle
    X: np.ndarray            # (n, 4) the observer's gains
    P: np.ndarray            # (n, p) the law's numbers (pure_params)
    use_obs: np.ndarray      # (n,) bool: the observer term is applied
    # --- the state-mode sensors' noise and the friction's draws (numpy's normals, a block of periods)
    noisy: np.ndarray        # (n,) bool
    std: np.ndarray          # (n, 4) noise standard deviations
    D_w_mean: np.ndarray     # (n,) wheel friction mean
    D_w_sd: np.ndarray       # (n,) and standard deviation
    D_w_random: np.ndarray   # (n,) bool: D_w drawn per period
    Nw: np.ndarray           # (n, block) the D_w draws
    Z: np.ndarray            # (n, block, 4) the sensors' draws
    # --- each scenario's state between calls (updated in place)
    x: np.ndarray            # (n, 4) plant state
    u_prev: np.ndarray       # (n,) previous torque
    z: np.ndarray            # (n, 2) observer state
    prev: np.ndarray         # (n, 4) previous measured state
    s: np.ndarray            # (n,) the law's state
    qx: np.ndarray           # (n, delay + 1, 6) measurement delay queue
    qa: np.ndarray           # (n, act_delay + 1) actuator delay queue
    active: np.ndarray       # (n,) bool: not fallen, not ended
    # --- the results (updated in place)
    t_fall: np.ndarray       # (n,) time of the fall (NaN: none)
    steps: np.ndarray        # (n,) int64 periods integrated
    acc: np.ndarray          # (n, 15) the window's sums of squares and counts (batch_compiled.window_sums_metrics)
    ext: np.ndarray          # (n, 3) max, min, max |.| of theta_b in the window
    # --- scratch: the stage torques
    T: np.ndarray            # (block, 2, 2 substeps + 1) shared stage torques, per period
    tau1: np.ndarray         # (2 substeps + 1,) one scenario's, when not shared
    tau2: np.ndarray
    # --- the raw sensors and the estimator (core.plants.raw_sensors, core.estimators)
    raw: bool                # the plants measure raw
    RW: np.ndarray           # (n, 7) r, d, g, gyro_noise_std, gyro_bias_walk, accel_noise_std, counts
    RS: np.ndarray           # (n, 4) gyro bias, previous phi, D_w and command of the previous period
    raw_noisy: np.ndarray    # (n,) bool
    PE: np.ndarray           # (n, q) the estimator's numbers
    ES: np.ndarray           # (n, state_size) its state
    # --- the motor and the excitation (core.plants.drive, core.identification.excitation)
    motor_any: bool          # some scenario has the motor (the RK4 runs per scenario)
    MC: np.ndarray           # (n, 4) K_t, R, V_max, I_max (K_t = 0: none)
    EXT: np.ndarray          # (excitations, n_steps + 1) each distinct excitation's periods
    exi: np.ndarray          # (n,) int64 its row (< 0: none)
    # --- the verdict (core.closed_loop.trajectory.FAILURES)
    failure: np.ndarray      # (n,) int64 why each scenario failed: 0 it did not, 1 fall, 2 bad_command, 3 diverged
    # --- the motion references (compiled_motion.motion_arrays, docs/theory.md 6.11)
    motion: bool             # some scenario tracks a motion profile
    MO: np.ndarray           # (n, 10) compiled_motion.MO_COLUMNS: max_speed, ..., the hold's settle and filter
    PT: np.ndarray           # (n, points) the profile's times
    PV: np.ndarray           # (n, points) and its speeds
    NP: np.ndarray           # (n,) int64 its points (< 0: no motion)
    MS: np.ndarray           # (n, 16) compiled_motion.MS_COLUMNS: theta_w*, theta_w'*, v*, the law's second
                             # state (DSC's x_d), the hold's anchor and equilibrium (docs/theory.md 6.14)
    MA: np.ndarray           # (n, 9) the sums of core.closed_loop.metrics.motion_metrics (compiled_motion.motion_row)
