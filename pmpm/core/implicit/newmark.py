"""Newmark's rule on the grid nodes (average acceleration by default).

With the nodal displacement increment u of a step of length dt, and the step's start
velocity v_n and acceleration a_n,

    a_{n+1} = (u - dt v_n - dt^2 (1/2 - beta) a_n) / (beta dt^2)
    v_{n+1} = v_n + dt ((1 - gamma) a_n + gamma a_{n+1})

so d a_{n+1} / d u = 1 / (beta dt^2): the mass term of the tangent. beta = 1/4, gamma = 1/2 is
the trapezoidal rule: unconditionally stable, no numerical damping, second order, and its
period elongation is known in closed form (``period_elongation``).
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

    def __init__(self, dt, beta=0.25, gamma=0.5):
        self.dt, self.beta, self.gamma = dt, beta, gamma
        self.mass_factor = 1.0 / (beta * dt * dt)

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
