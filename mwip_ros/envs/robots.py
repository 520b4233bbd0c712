"""The vector env's robots drawn from a sweep spec: every episode a true robot as ``mwip_sweep`` draws it.

:class:`SpecRobots` draws pools of robots with the sweep's own :func:`mwip_ros.sweep.scenarios.expand` (the spec
with its ``seed`` set to the pool's seed and ``samples`` to the number of robots), and gives each robot's numbers
the plant stage reads: the eq. (2) terms of the true robot (:class:`mwip_ros.core.plants.model.PhysicalParams`) and its
D_b, with the scenario's noise seed.  The vector env steps every robot with the same nominal model, law, sensors and
drive, so a spec may vary the true robot only (``plant_sim.actual.*`` but the friction noise's D_w); ``MwipEnv``
takes any spec.
"""
from __future__ import annotations

import dataclasses
from typing import Tuple

import numpy as np

from mwip_ros import params as P
from mwip_ros.core.plants.model import PhysicalParams
from mwip_ros.sweep.scenarios import expand

__all__ = ["ROBOT_KEYS", "TERMS", "SpecRobots", "terms_of"]

ROBOT_KEYS = tuple(f"actual.{f.name}" for f in dataclasses.fields(PhysicalParams)) + ("actual.D_b",)
# what core.kernels.compiled.Inertia holds, then D_b, then r and g (the raw sensors)
TERMS = ("m11", "m12", "m22", "G_b")


def terms_of(values) -> Tuple[float, ...]:
    """(m11, m12, m22, G_b, D_b, r, g) of the true robot of the merged ``values``."""
    p = P.physical(values, "actual")
    return (*(float(getattr(p, t)) for t in TERMS), float(values["actual.D_b"]), float(p.r), float(p.g))


class SpecRobots:
    """Pools of ``n`` (or more, with grid axes) robots of the sweep spec ``spec``, each pool a seed's."""

    def __init__(self, spec, n: int):
        bad = [a.key for a in spec.axes if a.name not in ROBOT_KEYS]
        if bad:
            raise ValueError(f"sweep: the vector env draws the true robot only (plant_sim.actual.m_b, I_b, l, ...: "
                             f"every robot shares the rest); {spec.path} varies {bad[0]} (MwipEnv runs any spec)")
        self.spec, self.n = spec, n

    def pool(self, seed: int) -> Tuple[np.ndarray, np.ndarray]:
        """(a row (m11, m12, m22, G_b, D_b, r, g) per robot, their noise seeds): the scenarios of the spec with
        ``seed: seed`` and ``samples: n``, in the sweep's order."""
        sc = expand(dataclasses.replace(self.spec, seed=int(seed), samples=self.n))
        base = self.spec.base_values
        rows = np.array([terms_of({**base, **sc.overrides(i)}) for i in range(len(sc))])
        return rows, np.asarray(sc.seeds, dtype=np.int64)
