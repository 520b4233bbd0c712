"""MWIP rigid-body model: inertia terms, true plant dynamics, lumped disturbance.

Equation numbers are the paper's (DSCNDO, see ``docs/theory.md``); where the paper's
recovered text is wrong, the code follows the corrected form given in docs/theory.md
(noted as *fix*).

The state is one :class:`State` ``(theta_w, theta_b, dtheta_w, dtheta_b)`` (rad, rad/s),
passed whole to the model, the observer and the control law; ``q = x[:2]`` and
``dq = x[2:]``.  Torque ``u`` is in N m on the wheel.  Pure functions of floats, a named
tuple and small frozen dataclasses; nothing imports ROS.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import NamedTuple, Tuple, Union

import numpy as np

# a number, or a numpy array of them: the scalar functions run over a batch's columns too (``m = numpy``)
Real = Union[float, np.ndarray]

__all__ = ["State", "PhysicalParams", "Friction", "Sinusoid", "mass_matrix", "coriolis_gravity", "accel",
           "plant_accel", "lumped_disturbance", "nominal_accel", "semi_strict_feedback", "x1_of"]


class State(NamedTuple):
    """The MWIP state at one instant: wheel angle, body pitch and their rates."""

    theta_w: float   # wheel rotation [rad]
    theta_b: float   # body pitch from upright [rad]
    dtheta_w: float  # [rad/s]
    dtheta_b: float  # [rad/s]

    @property
    def q(self) -> Tuple[float, float]:
        return self[0], self[1]

    @property
    def dq(self) -> Tuple[float, float]:
        return self[2], self[3]


@dataclass(frozen=True)
class PhysicalParams:
    """Rigid-body parameters of one MWIP (true or nominal), SI units."""

    m_b: float  # body mass [kg]
    m_w: float  # wheel mass [kg]
    I_b: float  # body inertia about the axle [kg m^2]
    I_w: float  # wheel inertia [kg m^2]
    l: float    # axle to body centre of gravity [m]
    r: float    # wheel radius [m]
    g: float    # gravitational acceleration [m/s^2]

    @cached_property
    def m11(self) -> float:
        return (self.m_b + self.m_w) * self.r ** 2 + self.I_w  # eq. (2)

    @cached_property
    def m12(self) -> float:
        return self.m_b * self.l * self.r  # eq. (2)

    @cached_property
    def m22(self) -> float:
        return self.m_b * self.l ** 2 + self.I_b  # eq. (2)

    @cached_property
    def G_b(self) -> float:
        return self.m_b * self.g * self.l  # eq. (2)

    @cached_property
    def A_bar(self) -> float:
        """m11 m22 - m12^2 > 0 (eq. 38)."""
        return self.m11 * self.m22 - self.m12 ** 2


@dataclass(frozen=True)
class Friction:
    """Viscous friction of the true plant: D_b (drive) and D_w (ground)."""

    D_b: float
    D_w: float


@dataclass(frozen=True)
class Sinusoid:
    """``amplitude * sin(omega * t + phase)``; used for tau_ext1, tau_ext2."""

    amplitude: float = 0.0
    omega: float = 0.0
    phase: float = 0.0

    def __call__(self, t: float) -> float:
        return self.amplitude * math.sin(self.omega * t + self.phase)

    def at(self, t: float, m=math):
        """The value at ``t`` with the math namespace ``m`` (``numpy`` when the fields are arrays)."""
        return self.amplitude * m.sin(self.omega * t + self.phase)


def mass_matrix(p: PhysicalParams, x) -> np.ndarray:
    """M(q) of eq. (4): wheel row and the *sum* of the two rows of eq. (1)."""
    c = p.m12 * math.cos(x[1])
    return np.array([[p.m11, c], [p.m11 + c, p.m22 + c]])


def coriolis_gravity(p: PhysicalParams, x) -> np.ndarray:
    """N(q, q') of eq. (4)."""
    s = math.sin(x[1])
    cent = p.m12 * x[3] ** 2 * s
    return np.array([-cent, -p.G_b * s - cent])


def accel(p: PhysicalParams, D_w: Real, D_b: Real, x, u: Real, tau_ext1: float,
          tau_ext2: float, m=math) -> Tuple[float, float]:
    """True accelerations (theta_w'', theta_b'') of eq. (1) with eq. (3)'s disturbances, as floats.

    ``x`` is a :class:`State` (or any 4-tuple in its order).  *fix*: the left sides of
    eq. (1) are accelerations; tau_ext1 enters the wheel row and tau_ext2 the sum of
    both rows, so the body row gets tau_ext2 - tau_ext1.  Scalar on purpose: the plant
    calls it 4 x ``substeps`` times per period.  ``m`` is the math namespace: ``math`` for
    floats, ``numpy`` for arrays of scenarios (the batch simulator); the same arithmetic
    serves both.
    """
    _, theta_b, dtheta_w, dtheta_b = x
    s = m.sin(theta_b)
    mc = p.m12 * m.cos(theta_b)
    m11, m22 = p.m11, p.m22
    rhs_w = u - (D_w + D_b) * dtheta_w + D_b * dtheta_b + p.m12 * dtheta_b * dtheta_b * s + tau_ext1  # eq. (1), row 1
    rhs_b = -u - D_b * (dtheta_b - dtheta_w) + p.G_b * s + (tau_ext2 - tau_ext1)                     # eq. (1), row 2
    det = m11 * m22 - mc * mc
    return (m22 * rhs_w - mc * rhs_b) / det, (m11 * rhs_b - mc * rhs_w) / det


def plant_accel(p: PhysicalParams, fr: Friction, x, u: float, tau_ext1: float, tau_ext2: float) -> np.ndarray:
    """``accel`` with a ``Friction``, as a vector [theta_w'', theta_b'']."""
    return np.array(accel(p, fr.D_w, fr.D_b, x, u, tau_ext1, tau_ext2))


def lumped_disturbance(nominal: PhysicalParams, x, ddq, u: float, m=math) -> Tuple[float, float]:
    """True tau_d = M_hat(q) q'' + N_hat(q, q') - [u, 0]^T (eq. 6-7), written out for the 2x2 case."""
    s = m.sin(x[1])
    mc = nominal.m12 * m.cos(x[1])
    cent = nominal.m12 * x[3] * x[3] * s
    return (nominal.m11 * ddq[0] + mc * ddq[1] - cent - u,
            (nominal.m11 + mc) * ddq[0] + (nominal.m22 + mc) * ddq[1] - nominal.G_b * s - cent)


def nominal_accel(nominal: PhysicalParams, x, u: float, tau_d) -> np.ndarray:
    """Accelerations of the nominal model driven by tau_d: solve eq. (7) for q''."""
    rhs = np.array([u, 0.0]) + np.asarray(tau_d) - coriolis_gravity(nominal, x)
    return np.linalg.solve(mass_matrix(nominal, x), rhs)


def semi_strict_feedback(nominal: PhysicalParams, x, u: float, tau_d) -> Tuple[float, float, float]:
    """(x1', x2', x4') of eq. (18a)/(18b) for x = (x1, x2, x3, x4) (eq. 16)."""
    x1, x2, x3, x4 = x
    p = nominal
    s = math.sin(x2)
    mc = p.m12 * math.cos(x2)
    A = p.m11 * p.m22 - mc ** 2
    dx1 = -p.m12 * s * x3 * x4 + p.G_b * s + tau_d[1]  # eq. (18a)
    dx2 = x1 / (p.m22 + mc) - (p.m11 + mc) / (p.m22 + mc) * x4  # eq. (18b), first row
    dx4 = (p.m12 * p.m22 * s * ((x1 - (p.m11 + mc) * x4) / (p.m22 + mc)) ** 2
           - p.m12 * p.G_b * s * math.cos(x2)) / A \
        + (p.m22 + mc) * u / A \
        + ((p.m22 + mc) * tau_d[0] - mc * tau_d[1]) / A  # eq. (18b), second row
    return dx1, dx2, dx4


def x1_of(nominal: PhysicalParams, x) -> float:
    """x1 of eq. (16): (m11 + M_C12) x4 + (m22 + M_C12) x3 with x3 = theta_b', x4 = theta_w' (nominal)."""
    mc = nominal.m12 * math.cos(x[1])
    return (nominal.m11 + mc) * x[2] + (nominal.m22 + mc) * x[3]
