"""The batch compiled (:mod:`.batch`): the whole loop of a law with a pure step as one numba kernel
(:func:`.compiled.kernel_for`), the normal draws made here a block at a time, the metrics from the kernel's running
sums.
"""
from __future__ import annotations

from typing import Dict, Optional, Sequence, Type

import numpy as np

from .budget import window_samples
from .. import laws
from ..closed_loop.sim import ClosedLoop
from ..estimators import Estimator
from ..plants.sensing import NOISE_BLOCK, sensor_rng
from .batch_scenarios import BatchResult, _same

__all__ = ["window_sums_metrics"]

BLOCKS = 1   # noise blocks (core.plants.sensing.NOISE_BLOCK periods) drawn and run per call of the compiled loop


def _simulate_compiled(loops: Sequence[ClosedLoop], window: Sequence[float], law: Type[laws.Law], kernel,
                       raw: bool = False, estimator: Optional[Type[Estimator]] = None) -> BatchResult:
    """The whole loop compiled (``core.kernels.compiled._loop``), NOISE_BLOCK periods per call, the normal draws made
    here by each scenario's own generators in the scalar loop's order and handed in as blocks.  ``raw``: the
    plants measure raw (every one), ``estimator`` the class of their state estimator; the motor and the
    excitation are per scenario."""
    from .compiled import Inertia, load_cached
    from .compiled_motion import motion_arrays, motion_sums_metrics
    from ..identification.excitation import Excitation
    from .kernel_args import LoopArgs
    from ..plants.raw_sensors import raw_rng
    n = len(loops)
    pcs = [lp.plant for lp in loops]
    h = float(_same((pc.h for pc in pcs), "the control period"))
    substeps = int(_same((pc.substeps for pc in pcs), "the RK4 sub-steps"))
    n_steps = int(round(_same((lp.duration_s for lp in loops), "the duration") / h))
    scs = [pc.sensing for pc in pcs]
    counts = int(_same((sc.encoder_counts_per_rev for sc in scs), "the encoder resolution"))
    delay = int(_same((sc.delay_periods for sc in scs), "the measurement delay"))
    act_delay = int(_same((sc.actuator_delay_periods for sc in scs), "the actuator delay"))
    core: Type[laws.Law] = getattr(law, "base", law)
    raws = [pc.raw for pc in pcs if pc.raw is not None]   # every plant's with ``raw``
    arr = lambda rows: np.ascontiguousarray(np.array(rows, dtype=float).reshape(n, -1))  # noqa: E731
    terms = {}   # PhysicalParams -> its eq. (2) terms (the property's own function: no cached_property lock)

    def inertia(p):
        if p not in terms:
            terms[p] = [getattr(type(p), f).func(p) for f in Inertia._fields]
        return terms[p]
    act = arr([inertia(pc.actual) for pc in pcs])
    nom = arr([inertia(pc.nominal) for pc in pcs])
    D_b = arr([pc.D_b for pc in pcs])[:, 0].copy()
    sins = arr([[f.amplitude, f.omega, f.phase, g.amplitude, g.omega, g.phase]
                for f, g in ((pc.tau_ext1, pc.tau_ext2) for pc in pcs)])
    shared = bool(n) and bool((sins == sins[0]).all())
    T = np.zeros((NOISE_BLOCK * BLOCKS if shared else 1, 2, 2 * substeps + 1))
    limit = arr([pc.torque_limit for pc in pcs])[:, 0].copy()
    fall = arr([pc.fall_angle for pc in pcs])[:, 0].copy()
    X = arr([[float(v) for v in np.asarray(lp.X, dtype=float).ravel()] for lp in loops])
    P = arr([[float(v) for v in core.pure_params(lp.params)] for lp in loops]) if n else np.zeros((0, 0))
    use_obs = np.array([lp.use_observer for lp in loops], dtype=bool)
    noisy = np.array([sc.noisy and not raw for sc in scs], dtype=bool)   # raw: no state-mode sensors
    std = arr([list(sc.noise_std) for sc in scs])
    mean = np.array([pc.D_w_mean for pc in pcs], dtype=float)
    var = np.array([pc.D_w_variance for pc in pcs], dtype=float)
    random = np.flatnonzero(var != 0.0)
    dw_gens = [np.random.default_rng(int(pcs[i].seed)) for i in random]
    raw_noisy = np.array([rc.noisy for rc in raws] if raw else [False] * n, dtype=bool)
    # the four normals of a period: the state-mode sensors' (core.plants.sensing.Normals) or the raw sensors' (raw_rng)
    z_idx = np.flatnonzero(raw_noisy if raw else noisy)
    z_gens = [(raw_rng if raw else sensor_rng)(int(pcs[i].seed)) for i in z_idx]
    block = NOISE_BLOCK * BLOCKS   # periods per call: a generator's one draw of several blocks is the same sequence
    # the normal draws, a row per scenario (the compiled loop runs one scenario after another), filled in place
    Nw = np.zeros((n, block)) if len(random) else np.zeros((1, 1))
    Z = np.zeros((n, block, 4)) if len(z_idx) else np.zeros((1, 1, 4))
    rnd = var != 0.0
    sd = np.sqrt(var)
    x = arr([[float(v) for v in pc.initial] for pc in pcs])
    u_prev = np.zeros(n)
    z = np.zeros((n, 2))
    prev = np.zeros((n, 4))
    s = np.zeros(n)
    qx = np.zeros((n, delay + 1, 6))
    qa = np.zeros((n, act_delay + 1))
    active = np.ones(n, dtype=bool)
    t_fall = np.full(n, np.nan)
    failure = np.zeros(n, dtype=np.int64)
    steps = np.zeros(n, dtype=np.int64)
    acc = np.zeros((n, 15))   # sum of squares and count of theta_b, u, e1, e2, the estimate's errors, u applied
    # (finite samples); the periods saturated
    ext = np.empty((n, 3))   # max, min, max |.| of theta_b
    ext[:, 0], ext[:, 1], ext[:, 2] = -np.inf, np.inf, -np.inf
    tau1, tau2 = np.zeros(2 * substeps + 1), np.zeros(2 * substeps + 1)
    first_w, n_window = window_samples(n_steps, h, window)
    motion, MO, PT, PV, NP, MS, MA = motion_arrays(loops)   # the references (docs/theory.md 6.11), their metrics
    # the raw sensors (r, d, g, gyro_noise_std, gyro_bias_walk, accel_noise_std, counts) and their state (bias,
    # phi, D_w and the command of the previous period); the estimator's numbers and state
    RW = arr([[pc.actual.r, rc.offset, pc.actual.g, rc.gyro_noise_std, rc.gyro_bias_walk, rc.accel_noise_std,
               rc.encoder_counts_per_rev] for pc, rc in zip(pcs, raws)]) if raw else np.zeros((1, 7))
    RS = np.zeros((n, 4))
    if raw:
        RS[:, 0] = [rc.gyro_bias for rc in raws]
        made = {}

        def numbers(lp):
            key = (lp.estimator, lp.plant.nominal.r, lp.plant.nominal.g)
            if key not in made:
                made[key] = [float(v) for v in lp.estimator.make(h, key[1], key[2]).P]
            return made[key]
        PE = arr([numbers(lp) for lp in loops])
        assert estimator is not None   # raw: _raw_stage gave the scenarios' estimator class
        ES = np.zeros((n, estimator.state_size))
    else:
        PE, ES = np.zeros((1, 1)), np.zeros((1, 1))
    MC = arr([pc.motor_constants for pc in pcs])
    motor = MC[:, 0] > 0.0
    # the excitations: a row per distinct one, every period of the run
    # (core.identification.excitation.Excitation.series)
    series: Dict = {}
    exi = np.array([-1 if lp.excitation is None else series.setdefault(lp.excitation, len(series)) for lp in loops],
                   dtype=np.int64)
    EXT = np.zeros((max(1, len(series)), n_steps + 1))
    for cfg, row in series.items():
        EXT[row] = Excitation(cfg, h).series(n_steps + 1)
    with np.errstate(all="ignore"):
        for k0 in range(0, n_steps + 1, block):
            if not active.any():
                break
            k1 = min(k0 + block, n_steps + 1)   # the last block draws only what it runs: the same sequence
            for row, gen in enumerate(dw_gens):   # core.plants.plant.PlantSim._draw_D_w, a block at a time
                gen.standard_normal(out=Nw[random[row], :k1 - k0])
            for row, gen in enumerate(z_gens):    # core.plants.sensing.Normals
                gen.standard_normal(out=Z[z_idx[row], :k1 - k0])
            args = LoopArgs(   # the compiled loop's arguments by name (core.kernels.kernel_args), passed positionally
                k0=k0, k1=k1, n_steps=n_steps, h=h, substeps=substeps, first_w=first_w, n_window=n_window,
                counts=counts, delay=delay, act_delay=act_delay, observer_law=bool(law.observer),
                act=act, nom=nom, D_b=D_b, sins=sins, shared=shared, limit=limit, fall=fall, X=X, P=P, use_obs=use_obs,
                noisy=noisy, std=std, D_w_mean=mean, D_w_sd=sd, D_w_random=rnd, Nw=Nw, Z=Z,
                x=x, u_prev=u_prev, z=z, prev=prev, s=s, qx=qx, qa=qa, active=active,
                t_fall=t_fall, steps=steps, acc=acc, ext=ext, T=T, tau1=tau1, tau2=tau2,
                raw=raw, RW=RW, RS=RS, raw_noisy=raw_noisy, PE=PE, ES=ES,
                motor_any=bool(motor.any()), MC=MC, EXT=EXT, exi=exi, failure=failure,
                motion=motion, MO=MO, PT=PT, PV=PV, NP=NP, MS=MS, MA=MA)
            if k0 == 0:
                load_cached(kernel, tuple(args))
            kernel(*args)
        m = window_sums_metrics(acc, ext)
        if raw:
            m.update(_stage_metrics(acc, steps, h, motor, raw=True, motor_on=False))
        if motor.any():
            m.update(_stage_metrics(acc, steps, h, motor, raw=False, motor_on=True))
        if motion:
            m.update(motion_sums_metrics(MA, MO, NP))
    fallen = ~np.isnan(t_fall)
    upright = ~fallen & (n_steps * h >= window[1] - 1e-9)
    return BatchResult(fallen, t_fall, upright, m, int(steps.sum()), None, failure)


def window_sums_metrics(acc: np.ndarray, ext: np.ndarray) -> dict:
    """:func:`.metrics.window_metrics` from running sums: ``acc`` (N, 8) the sum of squares and the count of the
    finite samples of theta_b, u, e1, e2; ``ext`` (N, 3) the max, min and max |.| of the finite theta_b."""
    def rms(j):
        return np.where(acc[:, j + 1] > 0, np.sqrt(acc[:, j] / np.where(acc[:, j + 1] > 0, acc[:, j + 1], 1.0)),
                        np.nan)
    any_ = acc[:, 1] > 0
    return {"theta_b_p2p": np.where(any_, ext[:, 0] - ext[:, 1], np.nan), "theta_b_rms": rms(0),
            "theta_b_max_abs": np.where(any_, ext[:, 2], np.nan), "u_rms": rms(2), "tau_err1_rms": rms(4),
            "tau_err2_rms": rms(6)}


def _stage_metrics(acc: np.ndarray, steps: np.ndarray, h: float, motor: np.ndarray, raw: bool, motor_on: bool) -> dict:
    """The optional stages' metrics of :func:`.metrics.compute` from the compiled loop's sums (``acc`` columns 8 to
    14): the estimate's errors (raw sensors), the torque that acted and the time saturated (the scenarios with the
    motor; NaN for the others)."""
    def rms(j):
        ok = acc[:, j + 1] > 0
        return np.where(ok, np.sqrt(acc[:, j] / np.where(ok, acc[:, j + 1], 1.0)), np.nan)
    out = {}
    if raw:
        out["theta_b_est_err_rms"], out["dtheta_b_est_err_rms"] = rms(8), rms(10)
    if motor_on:
        out["u_applied_rms"] = np.where(motor, rms(12), np.nan)
        # whole run: the periods integrated with the drive saturated, times h (NaN for a run of one row)
        out["saturated_s"] = np.where(motor & (steps > 0), acc[:, 14] * h, np.nan)
    return out
