"""Independent finite-element model of the colliding disks of cases/disks_contact.toml: the
reference for their rebound (tests/unit/test_contact.py::test_disks_bounce_apart_elastically).

Two equal disks meeting head-on with equal and opposite velocities along their line of centres,
frictionless: by symmetry the plane midway between them is a rigid frictionless wall (the normal
velocity there is zero, the shear traction too). So one disk (radius R, plane strain, linear
elastic E, nu, rho) hits a rigid frictionless wall at speed v0 and leaves at e v0: e is the
rebound ratio of the MPM test, the centre-of-mass speed after separation over the impact speed.

The model shares no code with pmpm: linear triangles (scikit-fem's ``MeshTri.init_circle``,
refined), lumped (row-sum) mass, central differences at 0.5 of the stable step, and kinematic
contact, the standard treatment of a rigid wall with lumped masses: a node whose next position
would pass the wall gets the normal velocity that lands it on the wall (the contact force is
whatever stops it, never pulling), the tangential one untouched. Small strains (the impact
strain is about v0 / c_p ~ 0.1: linear kinematics is one of the model's differences from the
MPM's updated hypoelastic one, a few per cent of the stress at the peak).
Its own convergence (three meshes) gives its error (:func:`rebound_ratio`).
"""
import math

import numpy as np

__all__ = ["rebound_ratio", "converged_rebound"]


def _system(nrefs, R, E, nu, rho):
    """Mesh, lumped masses (per dof, x and y interleaved) and stiffness of the disk."""
    from skfem import Basis, BilinearForm, ElementTriP1, ElementVector, MeshTri, asm
    from skfem.models.elasticity import lame_parameters, linear_elasticity
    mesh = MeshTri.init_circle(nrefs).scaled(R)
    lam, mu = lame_parameters(E, nu)  # 3-D Lame constants: plane strain
    basis = Basis(mesh, ElementVector(ElementTriP1()))
    K = asm(linear_elasticity(lam, mu), basis).tocsr()

    @BilinearForm
    def mass(u, v, w):
        return rho * (u[0] * v[0] + u[1] * v[1])

    M = np.asarray(asm(mass, basis).sum(axis=1)).ravel()
    X = mesh.doflocs if hasattr(mesh, "doflocs") else mesh.p
    # dof order of ElementVector(P1): node k's x at nodal_dofs[0, k], y at nodal_dofs[1, k]
    ix, iy = basis.nodal_dofs[0], basis.nodal_dofs[1]
    h = min(np.linalg.norm(mesh.p[:, a] - mesh.p[:, b], axis=0).min()
            for a, b in ((mesh.t[0], mesh.t[1]), (mesh.t[1], mesh.t[2]), (mesh.t[2], mesh.t[0])))
    return mesh.p, K, M, ix, iy, h


def rebound_ratio(nrefs, R=0.2, E=1000.0, nu=0.3, rho=1000.0, v0=0.1 * math.sqrt(2.0)):
    """Rebound ratio of the disk on mesh refinement ``nrefs`` (centre-of-mass speed after the
    last node leaves the wall, over v0)."""
    P, K, M, ix, iy, h = _system(nrefs, R, E, nu, rho)
    n = len(M)
    x0 = P[0] + R  # the wall is x = 0; the disk touches it at t = 0
    c_p = math.sqrt(E * (1 - nu) / ((1 + nu) * (1 - 2 * nu)) / rho)
    dt = 0.5 * h / c_p  # below the lumped-mass P1 limit (about h / c_p)
    u = np.zeros(n)
    v = np.zeros(n)
    v[ix] = -v0
    mass = M[ix].sum()
    t, touched, free_since = 0.0, False, None
    while True:
        a = -(K @ u) / M
        v += dt * a
        # kinematic contact: the x velocity that would pass the wall lands the node on it
        xn = x0 + u[ix]
        nxt = xn + dt * v[ix]
        hit = nxt < 0.0
        v[ix[hit]] = -xn[hit] / dt
        u += dt * v
        t += dt
        if hit.any():
            touched, free_since = True, None
        elif touched:
            free_since = t if free_since is None else free_since
            # the centre-of-mass velocity is constant once free: a short wait for round-off
            if t - free_since > 20 * dt:
                return float(v[ix] @ M[ix] / mass) / v0
        if t > 20 * R / v0:
            raise RuntimeError("the disk did not leave the wall")


def converged_rebound(levels=(3, 4, 5)):
    """(e on the finest mesh, an error bound from the model's own convergence: the change from
    the second finest to the finest, which bounds the finest's error when the error at least
    halves per refinement, as the ratios returned show), and the per-level values."""
    values = [rebound_ratio(k) for k in levels]
    return values[-1], abs(values[-1] - values[-2]), values


if __name__ == "__main__":
    print(converged_rebound())
