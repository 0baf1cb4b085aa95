"""Fused kernels: several phases of the step in one particle pass (a measured prototype: the
solver does not call it, it measured no faster than the separate phases, docs/performance.md).

``kinematics_stress`` is the USL/MUSL tail in one pass: the strain increment from the grid
velocity, the volume update, the internal work before the stress update (the trapezoid rule's
first half), the elastic stress update with its second half (``elastic`` not None), and the
move. Without fusion these are g2p_kinematics, then the material's update_stress and two
stress_power passes (pmpm/core/kernels/transfer.py, grid_ops.py, the materials): four passes
over the particle arrays, and the strain increments stored and read three times. Those kernels
stay the reference that tests/unit/test_fused.py checks this one against (to round-off: only the
order of the internal-work sums differs).

The arithmetic of every particle is that of the reference kernels, in the same order: the
velocity-gradient sums of transfer.g2p_kinematics, transfer.strain_increment, the elastic
increment of pmpm/physics/materials/linear_elastic.py and transfer.move.
"""
import numba as nb

from pmpm.core.kernels.transfer import _block_weights, _buffers, move, strain_increment
from pmpm.core.shape import BLOCK, stencil
from pmpm.physics.materials.linear_elastic import elastic_increment

__all__ = ["kinematics_stress"]


@nb.njit(cache=True)
def kinematics_stress(x, m, vol, strain, stress, de, vel_field, dx, dt, elastic,
                      gravity, load_id, load_w, load_vec,
                      G, ox, oy, origin, inv_h, ncx, ncy, shape):
    """Strain increment from grid field ``vel_field`` (paper eq. 6), volume, internal work,
    (``elastic`` not None) the elastic stress update, and the move x += dx.

    Parameters
    ----------
    x, m, vol, strain, dx, gravity, load_id, load_w, load_vec, G ... shape
        As for transfer.g2p_kinematics (``strain`` may be None; ``dx`` is the move computed by
        g2p_velocity).
    stress : ndarray (N, 4)
        Read for the internal work; updated in place when ``elastic`` is given.
    de : ndarray (N, 3) or None
        Receives the strain increments (the material update that follows needs them); None
        with ``elastic``, where nothing else reads them.
    elastic : (E, nu, plane_strain) or None
        One linear elastic material for every particle: its update is done here.

    Returns
    -------
    (external work over the moves, internal work): the internal work is sum_p V_p (1/2 sigma_old
    + 1/2 sigma_new) : de_p with ``elastic``, else its first half sum_p 1/2 V_p sigma_old : de_p
    (the caller adds the second half after the material's update).
    """
    work = 0.0
    power = 0.0
    K = stencil(shape)
    S, I0, J0, WX, WY = _buffers(shape)
    n = x.shape[0]
    c = dt * inv_h
    for p0 in range(0, n, BLOCK):
        nq = min(BLOCK, n - p0)
        _block_weights(x, p0, nq, origin, inv_h, ncx, ncy, shape, S, I0, J0, WX, WY)
        for q in range(nq):
            p = p0 + q
            lxx = 0.0
            lxy = 0.0
            lyx = 0.0
            lyy = 0.0
            for a in range(K):
                ii = I0[q] + a - ox
                wa = WX[a, q]
                ga = WX[K + a, q]
                for b in range(K):
                    jj = J0[q] + b - oy
                    dnx = ga * WY[b, q]
                    dny = wa * WY[K + b, q]
                    gvx = G[ii, jj, vel_field]
                    gvy = G[ii, jj, vel_field + 1]
                    lxx += gvx * dnx
                    lxy += gvx * dny
                    lyx += gvy * dnx
                    lyy += gvy * dny
            dexx = c * lxx
            deyy = c * lyy
            dgxy = c * (lxy + lyx)
            if de is not None:
                strain_increment(p, c, lxx, lxy, lyx, lyy, de, None, strain, vol, None, None, None)
            else:
                if strain is not None:
                    strain[p, 0] += dexx
                    strain[p, 1] += deyy
                    strain[p, 2] += dgxy
                vol[p] *= 1.0 + dexx + deyy
            v = vol[p]
            power += 0.5 * v * (stress[p, 0] * dexx + stress[p, 1] * deyy + stress[p, 2] * dgxy)
            if elastic is not None:
                ds = elastic_increment(elastic[0], elastic[1], elastic[2], dexx, deyy, dgxy)
                sxx = stress[p, 0] + ds[0]
                syy = stress[p, 1] + ds[1]
                sxy = stress[p, 2] + ds[2]
                stress[p, 0] = sxx
                stress[p, 1] = syy
                stress[p, 2] = sxy
                stress[p, 3] += ds[3]
                power += 0.5 * v * (sxx * dexx + syy * deyy + sxy * dgxy)
            work += move(p, x, dx, m, gravity, load_id, load_w, load_vec)
    return work, power
