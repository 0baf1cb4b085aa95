"""Newmark's rule on the grid nodes (average acceleration by default).

With the nodal displacement increment u of a step of length dt, and the step's start
velocity v_n and acceleration a_n,

    a_{n+1} = (u - dt v_n - dt^2 (1/2 - beta) a_n) / (beta dt^2)
    v_{n+1} = v_n + dt ((1 - gamma) a_n + gamma a_{n+1})

so d a_{n+1} / d u = 1 / (beta dt^2): the mass term of the tangent. beta = 1/4, gamma = 1/2 is
the trapezoidal rule: unconditionally stable, no numerical damping, second order, and its
period elongation is known in closed form (``period_elongation``).

HHT-alpha (Hilber, Hughes & Taylor 1977), ``alpha`` in [-1/3, 0]: the equation of motion is
taken at n + 1 + alpha for the forces, M a_{n+1} = (1 + alpha) F_{n+1} - alpha F_n (F = f_ext +
f_int), with beta = (1 - alpha)^2 / 4, gamma = (1 - 2 alpha) / 2: still second order and
unconditionally stable, and it damps the modes with omega dt >> 1 (the spurious high modes of
the grid) while leaving the low ones almost untouched. alpha = 0 is the trapezoidal rule.
"""
import math

__all__ = ["Newmark", "period_elongation"]


class Newmark:
    """The rule's coefficients for one step of length ``dt``.

    Parameters
    ----------
    dt : float
    beta, gamma : float
    """

    def __init__(self, dt, alpha=0.0):
        self.dt, self.alpha = dt, alpha
        self.beta = 0.25 * (1.0 - alpha) ** 2
        self.gamma = 0.5 - alpha
        self.mass_factor = 1.0 / (self.beta * dt * dt)

    def predictor(self, v, a):
        """The displacement increment if the acceleration stayed a_n (Newton's first guess)."""
        return self.dt * v + 0.5 * self.dt * self.dt * a

    def acceleration(self, u, v, a):
        """a_{n+1} of the increment u (arrays of nodal vectors)."""
        dt = self.dt
        return (u - dt * v - dt * dt * (0.5 - self.beta) * a) * self.mass_factor

    def velocity_change(self, a_old, a_new):
        """v_{n+1} - v_n."""
        return self.dt * ((1.0 - self.gamma) * a_old + self.gamma * a_new)


def period_elongation(omega, dt):
    """T_numerical / T of the trapezoidal rule for an oscillator of angular frequency omega:
    its amplification matrix rotates by 2 atan(omega dt / 2) per step (instead of omega dt),
    so the period grows by (omega dt / 2) / atan(omega dt / 2)."""
    half = 0.5 * omega * dt
    return half / math.atan(half)
