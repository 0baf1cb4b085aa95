"""An independent finite-element model of the round-notched steel plate pulled to ductile
fracture initiation (issue 39, "notched or grooved flat specimen"), NumPy only.

The specimen (:data:`SPECIMEN`): a plate 100 x 40 mm, 10 mm thick, with two semicircular edge
notches of radius 8 mm at mid-length (ligament 24 mm), plane stress; held on its left face, its
right face pulled at 2 m/s from rest. The material is the bilinear von Mises steel with linear
Ziegler kinematic hardening (post-yield tangent alpha E) and the void growth damage of Kanvinde
& Deierlein, dD = d(eps_p_eq) / (eta exp(-1.5 T)), no damage at T <= -1/3, T from the Cauchy
stress at the end of each increment with szz = 0 (docs/fracture.md). The first point whose
damage reaches 1 marks fracture initiation; with a ``characteristic_length`` l* in the specimen
(the nonlocal criterion), the first point where the damage averaged over l* reaches 1 and its
own damage too (pmpm's criterion: exceeded at the point and over l*): a Gaussian weight of
variance l*^2 / 12 per axis (that of a uniform average over a segment of length l*) on the Gauss
points' current positions, cut at 3 standard deviations, weighted by the points' areas and
renormalised over the material within reach (neighbour lists built once on the initial points,
1.5 times wider than the cut), evaluated each step once some point's own damage has reached 1
(the average cannot exceed the largest value). ``snapshots`` records the Gauss points'
positions, eps_p_eq, damage and stresses at given times (the diagnosis of docs/fracture.md).

This model shares no code with pmpm (it imports nothing from it):

* **mesh**: structured 4-node quadrilaterals; each column of nodes at abscissa x spans the
  plate's section there, from the notch's arc y_b(x) = sqrt(R^2 - (x - 50 mm)^2) to 40 mm - y_b,
  so the notch roots are exact;
* **elements**: bilinear, 2 x 2 Gauss points, updated Lagrangian (shape-function gradients on
  the current coordinates, strain increment sym(grad v) dt, the thickness kept constant and no
  stress rotation: pmpm's default without ``large_rotations``, whose rotations here are small);
* **material update**: backward Euler written directly in plane stress: with the relative
  stress xi = sigma - back, the flow d eps_p = d lambda P xi / sigma_y and the back stress
  d back = d lambda c xi / sigma_y, xi = (I + d lambda (C P / sigma_y + c / sigma_y I))^-1 xi_trial
  and d lambda solves Phi(xi) = sigma_y by a safeguarded Newton iteration on batched 3 x 3
  solves (pmpm instead scales xi in the eigenbasis of C and P, Simo & Taylor's projection);
* **loop**: the time loop is one numba function over elements and Gauss points (the
  NumPy :class:`PlaneStressJ2` is its point update's vectorised twin, kept for checks);
* **mass and time**: row-sum lumped mass, central differences, the step a fraction of the
  smallest element edge over the plane-stress wave speed;
* **force**: the support's reaction is the internal force at the held nodes (their
  acceleration is zero), averaged over sampling windows like pmpm's reactions.

Run ``python tests/verification/notched_specimen_fe_model.py 2 1`` to print initiation at two
element sizes (mm).
"""
import math
import sys

import numba as nb
import numpy as np

__all__ = ["SPECIMEN", "mesh", "run", "polygon"]

#: the specimen and its material (SI units)
SPECIMEN = {
    "length": 0.1, "width": 0.04, "thickness": 0.01, "radius": 0.008, "pull": 2.0,
    "E": 200e9, "nu": 0.3, "density": 7850.0, "yield_stress": 355e6, "hardening": 0.01,
    "eta": 0.3, "fracture_energy": 2.0e4, "characteristic_length": 6.0e-3,
}


def _notch_depth(x, sp):
    """y_b(x): the depth of the lower notch at abscissa x."""
    d = x - 0.5 * sp["length"]
    r = sp["radius"]
    return np.where(np.abs(d) < r, np.sqrt(np.maximum(r * r - d * d, 0.0)), 0.0)


def polygon(sp=SPECIMEN, per_arc=64):
    """The specimen's outline as polygon vertices (counter-clockwise), the arcs by ``per_arc``
    chords (for a particle code's polygon body)."""
    L, W, r, xc = sp["length"], sp["width"], sp["radius"], 0.5 * sp["length"]
    a = np.linspace(np.pi, 0.0, per_arc + 1)            # lower notch, left to right
    lower = np.c_[xc + r * np.cos(a), r * np.sin(a)]
    upper = np.c_[xc - r * np.cos(a), W - r * np.sin(a)]  # upper notch, right to left
    pts = [[0.0, 0.0], *lower.tolist(), [L, 0.0], [L, W], *upper.tolist(), [0.0, W]]
    return [[float(round(x, 12)), float(round(y, 12))] for x, y in pts]


def mesh(h, sp=SPECIMEN):
    """Nodes (n, 2), elements (m, 4) counter-clockwise, for elements about ``h`` wide."""
    nx = int(round(sp["length"] / h))
    ny = int(round(sp["width"] / h))
    xs = np.linspace(0.0, sp["length"], nx + 1)
    yb = _notch_depth(xs, sp)
    t = np.linspace(0.0, 1.0, ny + 1)
    X = np.repeat(xs, ny + 1)
    Y = (yb[:, None] + t[None, :] * (sp["width"] - 2 * yb)[:, None]).ravel()
    nodes = np.c_[X, Y]
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    n0 = (i * (ny + 1) + j).ravel()
    elems = np.c_[n0, n0 + ny + 1, n0 + ny + 2, n0 + 1]
    return nodes, elems


_G = 1.0 / math.sqrt(3.0)
_GP = np.array([[-_G, -_G], [_G, -_G], [_G, _G], [-_G, _G]])
_XI = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
# dN_a/d(xi, eta) at each Gauss point: (gp, a, 2)
_DN = 0.25 * np.stack([np.stack([_XI[:, 0] * (1 + _XI[:, 1] * g[1]), _XI[:, 1] * (1 + _XI[:, 0] * g[0])], axis=1)
                       for g in _GP])
_N = 0.25 * np.array([[(1 + _XI[a, 0] * g[0]) * (1 + _XI[a, 1] * g[1]) for a in range(4)] for g in _GP])


def _gradients(x, elems):
    """dN/dx, dN/dy (m, gp, a) and det J (m, gp) on the coordinates ``x``."""
    X, Y = x[elems, 0], x[elems, 1]                      # (m, a)
    dxi, deta = _DN[..., 0], _DN[..., 1]                 # (gp, a)
    j00, j01 = X @ dxi.T, Y @ dxi.T                      # d(x, y)/d xi   (m, gp)
    j10, j11 = X @ deta.T, Y @ deta.T                    # d(x, y)/d eta
    det = j00 * j11 - j01 * j10
    dndx = (j11[..., None] * dxi - j01[..., None] * deta) / det[..., None]
    dndy = (-j10[..., None] * dxi + j00[..., None] * deta) / det[..., None]
    return dndx, dndy, det


class PlaneStressJ2:
    """Bilinear von Mises with Ziegler kinematic hardening in plane stress (module doc)."""

    P = np.array([[1.0, -0.5, 0.0], [-0.5, 1.0, 0.0], [0.0, 0.0, 3.0]])

    def __init__(self, E, nu, sy, alpha):
        self.sy = sy
        self.C = E / (1 - nu * nu) * np.array([[1.0, nu, 0.0], [nu, 1.0, 0.0], [0.0, 0.0, 0.5 * (1 - nu)]])
        c = alpha * E / (1 - alpha)
        A = self.C @ self.P / sy + c / sy * np.eye(3)
        # (I + d lambda A)^-1 through A's eigenvalues (real and positive: A is similar to a
        # symmetric positive definite matrix, C^1/2 P C^1/2 / sy + k I)
        a, V = np.linalg.eig(A)
        self.a, self.V, self.Vinv = a.real, V.real, np.linalg.inv(V.real)
        self.c = c

    def phi(self, xi):
        return np.sqrt(np.maximum(np.einsum("ni,ij,nj->n", xi, self.P, xi), 0.0))

    def update(self, sig, back, de):
        """New (sigma, back, d lambda) for stresses (n, 3), back stresses (n, 3), strain
        increments (n, 3) with engineering shear."""
        trial = sig + de @ self.C.T
        xi_tr = trial - back
        f = self.phi(xi_tr)
        dl = np.zeros(len(sig))
        y = f > self.sy * (1 + 1e-12)
        if not y.any():
            return trial, back.copy(), dl
        zt = xi_tr[y] @ self.Vinv.T                      # trial relative stress in A's eigenbasis
        lam = np.zeros(len(zt))
        lo = np.zeros(len(zt))
        hi = np.full(len(zt), np.inf)
        for _ in range(60):
            den = 1.0 + lam[:, None] * self.a[None]
            xi = (zt / den) @ self.V.T
            ph = self.phi(xi)
            g = ph - self.sy
            lo = np.where(g > 0, lam, lo)
            hi = np.where(g <= 0, lam, hi)
            dxi = -(zt * self.a[None] / den ** 2) @ self.V.T
            dg = np.einsum("ni,ij,nj->n", xi, self.P, dxi) / np.maximum(ph, 1e-300)
            step = lam - g / dg
            bad = ~np.isfinite(step) | (step <= lo) | (step >= hi)
            mid = np.where(np.isfinite(hi), 0.5 * (lo + hi), 2 * lam + 1e-12)
            lam = np.where(bad, mid, step)
            if np.all(np.abs(g) <= 1e-12 * self.sy):
                break
        xi = (zt / (1.0 + lam[:, None] * self.a[None])) @ self.V.T
        new_back = back.copy()
        new_back[y] = back[y] + lam[:, None] * self.c / self.sy * xi
        new_sig = trial.copy()
        new_sig[y] = xi + new_back[y]
        dl[y] = lam
        return new_sig, new_back, dl


def triaxiality(sig):
    """sigma_m / sigma_eq of plane-stress stresses (n, 3) (szz = 0)."""
    seq = np.sqrt(np.maximum(sig[:, 0] ** 2 - sig[:, 0] * sig[:, 1] + sig[:, 1] ** 2 + 3 * sig[:, 2] ** 2, 0.0))
    return np.where(seq > 0, (sig[:, 0] + sig[:, 1]) / 3.0 / np.where(seq > 0, seq, 1.0), 0.0)


@nb.njit(cache=True, inline="always")
def _phi(x0, x1, x2):
    return math.sqrt(max(x0 * x0 - x0 * x1 + x1 * x1 + 3.0 * x2 * x2, 0.0))


@nb.njit(cache=True)
def _point_update(sig, back, de, C, a, V, Vinv, sy, c):
    """One Gauss point's increment (PlaneStressJ2.update, scalar, written out): returns d lambda."""
    t0 = sig[0] + C[0, 0] * de[0] + C[0, 1] * de[1] + C[0, 2] * de[2]
    t1 = sig[1] + C[1, 0] * de[0] + C[1, 1] * de[1] + C[1, 2] * de[2]
    t2 = sig[2] + C[2, 0] * de[0] + C[2, 1] * de[1] + C[2, 2] * de[2]
    x0, x1, x2 = t0 - back[0], t1 - back[1], t2 - back[2]
    if _phi(x0, x1, x2) <= sy * (1.0 + 1e-12):
        sig[0], sig[1], sig[2] = t0, t1, t2
        return 0.0
    # the trial relative stress in A's eigenbasis
    z0 = Vinv[0, 0] * x0 + Vinv[0, 1] * x1 + Vinv[0, 2] * x2
    z1 = Vinv[1, 0] * x0 + Vinv[1, 1] * x1 + Vinv[1, 2] * x2
    z2 = Vinv[2, 0] * x0 + Vinv[2, 1] * x1 + Vinv[2, 2] * x2
    lam, lo, hi = 0.0, 0.0, math.inf
    for _ in range(60):
        y0, y1, y2 = z0 / (1.0 + lam * a[0]), z1 / (1.0 + lam * a[1]), z2 / (1.0 + lam * a[2])
        x0 = V[0, 0] * y0 + V[0, 1] * y1 + V[0, 2] * y2
        x1 = V[1, 0] * y0 + V[1, 1] * y1 + V[1, 2] * y2
        x2 = V[2, 0] * y0 + V[2, 1] * y1 + V[2, 2] * y2
        ph = _phi(x0, x1, x2)
        g = ph - sy
        if abs(g) <= 1e-12 * sy:
            break
        if g > 0:
            lo = lam
        else:
            hi = lam
        w0, w1, w2 = -y0 * a[0] / (1.0 + lam * a[0]), -y1 * a[1] / (1.0 + lam * a[1]), -y2 * a[2] / (1.0 + lam * a[2])
        d0 = V[0, 0] * w0 + V[0, 1] * w1 + V[0, 2] * w2
        d1 = V[1, 0] * w0 + V[1, 1] * w1 + V[1, 2] * w2
        d2 = V[2, 0] * w0 + V[2, 1] * w1 + V[2, 2] * w2
        dg = (x0 * (d0 - 0.5 * d1) + x1 * (d1 - 0.5 * d0) + 3.0 * x2 * d2) / ph
        step = lam - g / dg
        if not math.isfinite(step) or step <= lo or step >= hi:
            step = 0.5 * (lo + hi) if math.isfinite(hi) else 2.0 * lam + 1e-12
        lam = step
    y0, y1, y2 = z0 / (1.0 + lam * a[0]), z1 / (1.0 + lam * a[1]), z2 / (1.0 + lam * a[2])
    x0 = V[0, 0] * y0 + V[0, 1] * y1 + V[0, 2] * y2
    x1 = V[1, 0] * y0 + V[1, 1] * y1 + V[1, 2] * y2
    x2 = V[2, 0] * y0 + V[2, 1] * y1 + V[2, 2] * y2
    back[0] += lam * c / sy * x0
    back[1] += lam * c / sy * x1
    back[2] += lam * c / sy * x2
    sig[0], sig[1], sig[2] = x0 + back[0], x1 + back[1], x2 + back[2]
    return lam


@nb.njit(cache=True)
def _march(x, v, mass, elems, held, pulled, pull, dt, end_time, sample, thickness, eta,
           C, P, a, V, Vinv, sy, c, dN, Ng, stop_at_initiation, snap_times, sigma, nb_ptr, nb_idx):
    """Central differences to ``end_time`` (module doc). Returns (window ends, mean reaction,
    initiation time or -1, its point x, y, steps, and at each of ``snap_times`` the Gauss points'
    positions, equivalent plastic strains, damages and stresses)."""
    n, m = x.shape[0], elems.shape[0]
    sig = np.zeros((m, 4, 3))
    back = np.zeros((m, 4, 3))
    damage = np.zeros((m, 4))
    eq = np.zeros((m, 4))
    ksnap = snap_times.shape[0]
    snap_x = np.zeros((ksnap, m, 4, 2))
    snap_eq = np.zeros((ksnap, m, 4))
    snap_d = np.zeros((ksnap, m, 4))
    snap_s = np.zeros((ksnap, m, 4, 3))
    isnap = 0
    gx = np.zeros((m * 4, 2))      # the Gauss points' current positions (nonlocal criterion)
    gw = np.zeros(m * 4)           # and their volumes (over the thickness)
    fint = np.zeros((n, 2))
    nsamples = int(end_time / sample) + 2
    times = np.zeros(nsamples)
    forces = np.zeros(nsamples)
    ns = 0
    t, acc, acc_t, next_sample = 0.0, 0.0, 0.0, sample
    initiation, wx, wy, steps = -1.0, 0.0, 0.0, 0
    de = np.zeros(3)
    dndx = np.zeros(4)
    dndy = np.zeros(4)
    while t < end_time - 1e-15:
        for i in range(n):
            if held[i]:
                v[i, 0] = 0.0
                v[i, 1] = 0.0
            elif pulled[i]:
                v[i, 0] = pull
                v[i, 1] = 0.0
            x[i, 0] += dt * v[i, 0]
            x[i, 1] += dt * v[i, 1]
        fint[:] = 0.0
        failed_now = False
        for e in range(m):
            for g in range(4):
                j00 = j01 = j10 = j11 = 0.0
                for k in range(4):
                    nd = elems[e, k]
                    j00 += dN[g, k, 0] * x[nd, 0]
                    j01 += dN[g, k, 0] * x[nd, 1]
                    j10 += dN[g, k, 1] * x[nd, 0]
                    j11 += dN[g, k, 1] * x[nd, 1]
                det = j00 * j11 - j01 * j10
                for k in range(4):
                    dndx[k] = (j11 * dN[g, k, 0] - j01 * dN[g, k, 1]) / det
                    dndy[k] = (-j10 * dN[g, k, 0] + j00 * dN[g, k, 1]) / det
                lxx = lyy = lxy = lyx = 0.0
                for k in range(4):
                    nd = elems[e, k]
                    lxx += v[nd, 0] * dndx[k]
                    lyy += v[nd, 1] * dndy[k]
                    lxy += v[nd, 0] * dndy[k]
                    lyx += v[nd, 1] * dndx[k]
                de[0], de[1], de[2] = dt * lxx, dt * lyy, dt * (lxy + lyx)
                dl = _point_update(sig[e, g], back[e, g], de, C, a, V, Vinv, sy, c)
                s = sig[e, g]
                eq[e, g] += dl
                if dl > 0.0:
                    seq = math.sqrt(max(s[0] * s[0] - s[0] * s[1] + s[1] * s[1] + 3.0 * s[2] * s[2], 0.0))
                    T = (s[0] + s[1]) / (3.0 * seq) if seq > 0.0 else 0.0
                    if T > -1.0 / 3.0:
                        damage[e, g] += dl / (eta * math.exp(-1.5 * T))
                        if damage[e, g] >= 1.0 and initiation < 0.0 and sigma <= 0.0:
                            failed_now = True
                            wx = wy = 0.0
                            for k in range(4):
                                wx += Ng[g, k] * x[elems[e, k], 0]
                                wy += Ng[g, k] * x[elems[e, k], 1]
                w = thickness * det      # Gauss weight 1
                if sigma > 0.0:
                    gw[4 * e + g] = det
                    px = py = 0.0
                    for k in range(4):
                        px += Ng[g, k] * x[elems[e, k], 0]
                        py += Ng[g, k] * x[elems[e, k], 1]
                    gx[4 * e + g, 0], gx[4 * e + g, 1] = px, py
                for k in range(4):
                    nd = elems[e, k]
                    fint[nd, 0] += w * (s[0] * dndx[k] + s[2] * dndy[k])
                    fint[nd, 1] += w * (s[2] * dndx[k] + s[1] * dndy[k])
        if sigma > 0.0 and initiation < 0.0:
            # the nonlocal criterion: the index averaged over l* (a Gaussian of variance l*^2 / 12
            # per axis, cut at 3 sigma, renormalised over the material within reach), checked once
            # a Gauss point's own index has reached 1 (the average cannot exceed the largest)
            top = 0.0
            for e in range(m):
                for g in range(4):
                    top = max(top, damage[e, g])
            if top >= 1.0:
                cut2 = 9.0 * sigma * sigma
                for i in range(m * 4):
                    num = den = 0.0
                    for kk in range(nb_ptr[i], nb_ptr[i + 1]):
                        j = nb_idx[kk]
                        d2 = (gx[j, 0] - gx[i, 0]) ** 2 + (gx[j, 1] - gx[i, 1]) ** 2
                        if d2 <= cut2:
                            wj = gw[j] * math.exp(-0.5 * d2 / (sigma * sigma))
                            num += wj * damage[j // 4, j % 4]
                            den += wj
                    # and the point's own index (pmpm's fail_where: exceeded at the point and over l*)
                    if den > 0.0 and num >= den and damage[i // 4, i % 4] >= 1.0:
                        failed_now = True
                        wx, wy = gx[i, 0], gx[i, 1]
                        break
        react = 0.0
        for i in range(n):
            v[i, 0] -= dt * fint[i, 0] / mass[i]
            v[i, 1] -= dt * fint[i, 1] / mass[i]
            if held[i]:
                # the support holds its nodes still: its force on the plate is their internal force
                react += fint[i, 0]
        t += dt
        steps += 1
        acc += dt * react
        acc_t += dt
        if t >= next_sample - 1e-15:
            times[ns] = t
            forces[ns] = acc / acc_t
            ns += 1
            acc, acc_t = 0.0, 0.0
            next_sample += sample
        while isnap < ksnap and t >= snap_times[isnap] - 1e-15:
            for e in range(m):
                for g in range(4):
                    for k in range(4):
                        snap_x[isnap, e, g, 0] += Ng[g, k] * x[elems[e, k], 0]
                        snap_x[isnap, e, g, 1] += Ng[g, k] * x[elems[e, k], 1]
                    snap_eq[isnap, e, g] = eq[e, g]
                    snap_d[isnap, e, g] = damage[e, g]
                    for k in range(3):
                        snap_s[isnap, e, g, k] = sig[e, g, k]
            isnap += 1
        if failed_now:
            initiation = t
            if stop_at_initiation:
                break
    return times[:ns], forces[:ns], initiation, wx, wy, steps, snap_x, snap_eq, snap_d, snap_s


@nb.njit(cache=True)
def _neighbours(pts, radius):
    """For each point, the points within ``radius`` (itself included), as CSR arrays
    (pointers, indices), by binning the points in squares of side ``radius``."""
    n = pts.shape[0]
    x0, y0 = pts[:, 0].min(), pts[:, 1].min()
    nx = int((pts[:, 0].max() - x0) / radius) + 1
    ny = int((pts[:, 1].max() - y0) / radius) + 1
    cell = np.empty(n, np.int64)
    for i in range(n):
        cell[i] = int((pts[i, 0] - x0) / radius) * ny + int((pts[i, 1] - y0) / radius)
    order = np.argsort(cell)
    start = np.full(nx * ny + 1, n, np.int64)
    for k in range(n - 1, -1, -1):
        start[cell[order[k]]] = k
    for c in range(nx * ny - 1, -1, -1):
        start[c] = min(start[c], start[c + 1])
    counts = np.zeros(n + 1, np.int64)
    out = []
    for i in range(n):
        ci, cj = int((pts[i, 0] - x0) / radius), int((pts[i, 1] - y0) / radius)
        for a in range(max(ci - 1, 0), min(ci + 2, nx)):
            for b in range(max(cj - 1, 0), min(cj + 2, ny)):
                c = a * ny + b
                for k in range(start[c], start[c + 1]):
                    j = order[k]
                    if (pts[j, 0] - pts[i, 0]) ** 2 + (pts[j, 1] - pts[i, 1]) ** 2 <= radius * radius:
                        out.append(j)
                        counts[i + 1] += 1
    return np.cumsum(counts), np.array(out, dtype=np.int64)


def run(h, sp=SPECIMEN, end_time=2.0e-3, sample=1.0e-5, cfl=0.5, stop_at_initiation=True, snapshots=()):
    """Pull the specimen meshed at element size ``h``.

    Returns a dict: ``time`` (window ends, s), ``force`` (mean reaction Rx of the held face over
    each window, N: negative when the plate pulls the support), ``initiation`` (end time of the
    step in which the first Gauss point's damage reached 1, or None), ``where`` (its point),
    ``steps``.
    """
    nodes, elems = mesh(h, sp)
    mat = PlaneStressJ2(sp["E"], sp["nu"], sp["yield_stress"], sp["hardening"])
    rho = sp["density"]
    _, _, det = _gradients(nodes, elems)
    mass = np.bincount(elems.ravel(), weights=(rho * sp["thickness"] * det @ _N).ravel(), minlength=len(nodes))
    held = np.isclose(nodes[:, 0], 0.0)
    pulled = np.isclose(nodes[:, 0], sp["length"])
    c = math.sqrt(sp["E"] / (rho * (1 - sp["nu"] ** 2)))
    edges = np.linalg.norm(nodes[elems] - nodes[np.roll(elems, -1, axis=1)], axis=2)
    dt = cfl * edges.min() / c
    snap_times = np.sort(np.asarray(snapshots, dtype=np.float64).reshape(-1))
    lstar = sp.get("characteristic_length")
    sigma = lstar / math.sqrt(12.0) if lstar else 0.0
    if sigma > 0.0:
        # neighbour lists on the initial Gauss points, wide enough for the strains to initiation
        # (the kernel is cut at 3 sigma on the current positions)
        gp0 = np.einsum("ga,mai->mgi", _N, nodes[elems]).reshape(-1, 2)
        nb_ptr, nb_idx = _neighbours(np.ascontiguousarray(gp0), 1.5 * 3.0 * sigma)
    else:
        nb_ptr, nb_idx = np.zeros(1, np.int64), np.zeros(0, np.int64)
    times, forces, initiation, wx, wy, steps, sx, seq, sd, ss = _march(
        nodes.copy(), np.zeros_like(nodes), mass, elems.astype(np.int64), held, pulled, float(sp["pull"]), dt,
        float(end_time), float(sample), float(sp["thickness"]), float(sp["eta"]), mat.C, mat.P, mat.a, mat.V,
        mat.Vinv, float(sp["yield_stress"]), float(mat.c), np.ascontiguousarray(_DN), np.ascontiguousarray(_N),
        stop_at_initiation, snap_times, sigma, nb_ptr, nb_idx)
    return {"time": times, "force": forces, "initiation": initiation if initiation >= 0 else None,
            "where": (wx, wy) if initiation >= 0 else None, "steps": steps, "dt": dt, "elements": len(elems),
            "snapshots": {"time": snap_times, "x": sx, "eps_p_eq": seq, "damage": sd, "stress": ss}}


if __name__ == "__main__":
    for size in (sys.argv[1:] or ["2"]):
        r = run(float(size) * 1e-3)
        u = SPECIMEN["pull"] * r["initiation"] * 1e3 if r["initiation"] else float("nan")
        print(f"h = {size} mm: {r['elements']} elements, {r['steps']} steps, initiation at "
              f"u = {u:.4f} mm at {r['where']}, peak |force| {np.abs(r['force']).max() / 1e3:.2f} kN")
