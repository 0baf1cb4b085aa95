"""An independent finite-element model of the large-rotation cantilever (issue 20), NumPy only.

The benchmark of Sadeghirad, Brannon & Burghardt (IJNME 86, 2011): a 4 m x 1 m beam, compressible
neo-Hookean (E = 1e6 Pa, nu = 0.3, rho = 1050 kg/m^3), plane strain, clamped on its left face,
under gravity applied suddenly at t = 0. The published reference is a curve digitised from the
paper's figure (cases/hard/data/cantilever_fe_corner.csv): its mesh, element and integrator are not
known here, and two decimals of a digitised figure are all it carries. This model is a second,
converged reference that shares no code with pmpm:

* **elements**: 9-node Lagrange quadrilaterals (biquadratic, 3 x 3 Gauss points), total
  Lagrangian; quadratic elements do not shear-lock in bending, so a few elements through the
  depth are enough (the mesh study in ``converged_corner_history`` shows it);
* **material**: the same compressible neo-Hookean as the benchmark, written as the first
  Piola-Kirchhoff stress P = mu (F - F^-T) + lambda ln J F^-T (plane strain: F_zz = 1);
* **mass**: row-sum lumped (for the 9-node element all positive: 1/36 at corners, 4/36 at edge
  middles, 16/36 at the centre of the element's mass);
* **time**: central differences (leapfrog), explicit, the step a fraction of the smallest
  node spacing over the dilatational wave speed; this integrator conserves energy to the step's
  order, and ``energy_history`` reports the balance so a run can be judged on it.

Run ``python tests/verification/cantilever_fe_model.py`` to print the mesh study.
"""
import math
import sys

import numpy as np

LENGTH, DEPTH = 4.0, 1.0
E, NU, RHO, G = 1.0e6, 0.3, 1050.0, 9.8
MU = E / (2.0 * (1.0 + NU))
LAM = E * NU / ((1.0 + NU) * (1.0 - 2.0 * NU))   # plane strain: the 3-D Lame constant


def _q9_shape_gradients():
    """Shape-function gradients (in the parent square [-1, 1]^2) and weights at the 3 x 3 Gauss points."""
    g = math.sqrt(0.6)
    pts = np.array([-g, 0.0, g])
    wts = np.array([5.0, 8.0, 5.0]) / 9.0
    # 1-D quadratic Lagrange functions on nodes -1, 0, 1 and their derivatives
    def n1(s):
        return np.array([0.5 * s * (s - 1.0), 1.0 - s * s, 0.5 * s * (s + 1.0)])

    def d1(s):
        return np.array([s - 0.5, -2.0 * s, s + 0.5])

    grads, weights = [], []
    for a, sa in enumerate(pts):
        for b, sb in enumerate(pts):
            nx, dx = n1(sa), d1(sa)
            ny, dy = n1(sb), d1(sb)
            # local node (i, j) -> index 3 j + i (i along x, j along y)
            grad = np.zeros((9, 2))
            for j in range(3):
                for i in range(3):
                    grad[3 * j + i] = (dx[i] * ny[j], nx[i] * dy[j])
            grads.append(grad)
            weights.append(wts[a] * wts[b])
    return np.array(grads), np.array(weights)


class CantileverFE:
    """The clamped beam meshed by ``nx`` x ``ny`` 9-node elements."""

    def __init__(self, nx, ny):
        self.nx, self.ny = nx, ny
        hx, hy = LENGTH / nx, DEPTH / ny
        # nodes on a (2 nx + 1) x (2 ny + 1) lattice, index = row * (2 nx + 1) + column
        cols, rows = 2 * nx + 1, 2 * ny + 1
        X = np.stack(np.meshgrid(np.linspace(0, LENGTH, cols), np.linspace(0, DEPTH, rows)), -1).reshape(-1, 2)
        self.X = X
        ex, ey = np.meshgrid(np.arange(nx), np.arange(ny))
        ex, ey = ex.ravel(), ey.ravel()
        conn = np.empty((nx * ny, 9), dtype=np.int64)
        for j in range(3):
            for i in range(3):
                conn[:, 3 * j + i] = (2 * ey + j) * cols + (2 * ex + i)
        self.conn = conn
        grads, weights = _q9_shape_gradients()
        # the parent square maps to an hx x hy rectangle: d/dX = (2/hx) d/ds, d/dY = (2/hy) d/dt
        self.dN = grads * np.array([2.0 / hx, 2.0 / hy])          # (gauss, node, 2)
        self.wdet = weights * (hx * hy / 4.0)                        # (gauss,)
        lump = np.outer([1.0, 4.0, 1.0], [1.0, 4.0, 1.0]).T.ravel() / 36.0   # index 3 j + i
        mass = np.zeros(len(X))
        np.add.at(mass, conn, RHO * hx * hy * lump[None, :])
        self.mass = mass
        self.free = X[:, 0] > 1e-12                                  # the clamp: the face x = 0
        self.corner = int(np.argmin(np.hypot(X[:, 0] - LENGTH, X[:, 1])))
        self.node_spacing = min(hx, hy) / 2.0

    def internal_force_and_energy(self, u):
        ue = u[self.conn]                                            # (elements, 9, 2)
        F = np.eye(2) + np.einsum("eai,gaj->egij", ue, self.dN)
        J = F[..., 0, 0] * F[..., 1, 1] - F[..., 0, 1] * F[..., 1, 0]
        if np.any(J <= 0.0):
            raise FloatingPointError("an element inverted (J <= 0)")
        inv_t = np.stack([np.stack([F[..., 1, 1], -F[..., 1, 0]], -1),
                          np.stack([-F[..., 0, 1], F[..., 0, 0]], -1)], -2) / J[..., None, None]
        lnJ = np.log(J)
        P = MU * (F - inv_t) + (LAM * lnJ)[..., None, None] * inv_t
        fe = np.einsum("egij,gaj,g->eai", P, self.dN, self.wdet)
        f = np.zeros_like(u)
        np.add.at(f, self.conn, fe)
        # stored energy W = mu/2 (I1 - 3) - mu ln J + lambda/2 ln^2 J, with I1 = tr(F^T F) + 1
        I1m2 = np.einsum("egij,egij->eg", F, F) - 2.0
        W = 0.5 * MU * I1m2 - MU * lnJ + 0.5 * LAM * lnJ ** 2
        return f, float(np.einsum("eg,g->", W, self.wdet))

    def run(self, end_time=2.8, sample=0.005, courant=0.3):
        """Corner displacement uy(t) sampled every ``sample`` s, and the energy balance's worst error."""
        c = math.sqrt((LAM + 2.0 * MU) / RHO)
        dt = courant * self.node_spacing / c
        steps_per_sample = max(1, int(math.ceil(sample / dt)))
        dt = sample / steps_per_sample
        u = np.zeros_like(self.X)
        v = np.zeros_like(self.X)
        grav = np.zeros_like(self.X)
        grav[:, 1] = -G * self.mass
        free = self.free[:, None]
        f_int, W = self.internal_force_and_energy(u)
        a = np.where(free, (grav - f_int) / self.mass[:, None], 0.0)
        times, uy, worst = [0.0], [0.0], 0.0
        n_samples = int(round(end_time / sample))
        for k in range(n_samples):
            for _ in range(steps_per_sample):
                v_half = v + 0.5 * dt * a
                u = u + dt * v_half
                f_int, W = self.internal_force_and_energy(u)
                a = np.where(free, (grav - f_int) / self.mass[:, None], 0.0)
                v = v_half + 0.5 * dt * a
            kinetic = 0.5 * float(np.sum(self.mass[:, None] * v * v))
            gravity_work = float(np.sum(grav * u))
            worst = max(worst, abs(kinetic + W - gravity_work))
            times.append((k + 1) * sample)
            uy.append(u[self.corner, 1])
        return np.array(times), np.array(uy), worst / max(gravity_work_peak(self), 1.0), dt


def gravity_work_peak(model):
    """A scale for the energy balance: the gravity work of the whole mass falling one beam length."""
    return float(np.sum(model.mass)) * G * LENGTH


def corner_history(elements_through_depth, end_time=2.8, sample=0.005):
    ny = elements_through_depth
    return CantileverFE(4 * ny, ny).run(end_time, sample)


def main(argv):
    depths = [int(a) for a in argv] or [2, 4, 8]
    fe = np.loadtxt("cases/hard/data/cantilever_fe_corner.csv", delimiter=",", skiprows=1 + sum(1 for l in open("cases/hard/data/cantilever_fe_corner.csv") if l.startswith("#")))
    previous = None
    for ny in depths:
        import time
        t0 = time.time()
        t, uy, err, dt = corner_history(ny)
        keep = fe[:, 0] <= t[-1]
        rms = math.sqrt(np.mean((np.interp(fe[keep, 0], t, uy) - fe[keep, 1]) ** 2))
        line = (f"{4 * ny} x {ny} Q9 (node spacing {0.5 / ny:.4f} m), dt {dt:.2e} s: "
                f"largest drop {-uy.min():.4f} m at {t[np.argmin(uy)]:.3f} s, uy(2.6 s) {np.interp(2.6, t, uy):+.4f} m, "
                f"RMS vs digitised {rms:.4f} m, energy error {err:.1e} of m g L, {time.time() - t0:.0f} s")
        if previous is not None:
            line += f", RMS vs previous mesh {math.sqrt(np.mean((uy - previous) ** 2)):.4f} m"
        print(line, flush=True)
        np.savetxt(f"/tmp/cantilever_q9_{ny}.csv", np.column_stack([t, uy]), delimiter=",")
        previous = uy


if __name__ == "__main__":
    main(sys.argv[1:])
