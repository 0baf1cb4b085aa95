"""Kernels of multi-velocity-field contact (Bardenhagen, Brackbill & Sulsky 2000; Bardenhagen
et al. 2001): each contact body keeps its own nodal fields.

The body window is ``B[i - ox, j - oy, slot, field]`` (node-interleaved: the slots of a node
together, then the fields of a slot), with fields

    0 mass | 1, 2 momentum, then velocity after the grid update | 3, 4 force, then velocity change
    5, 6 mass gradient g = sum_p m_p grad N_i(x_p) (scattered with the mass) | 7, 8 re-mapped
    momentum (MUSL), then re-mapped velocity

i.e. the single-field layout of :mod:`pmpm.core.kernels` with the mass gradient inserted before the
re-mapped momentum, so ``B[:, :, s]`` is a single-field window on which the grid-node kernels of
:mod:`pmpm.core.kernels.grid_ops` run unchanged. A particle's slot is ``slot_of[body[p]]``. With one
slot every transfer here does exactly what its single-field twin in
:mod:`pmpm.core.kernels.transfer` does (the tests check it to the bit).

The contact correction (:func:`contact_update`) acts at nodes where two or more slots have mass:

* the centre-of-mass velocity v_cm = sum_b m_b v_b / sum_b m_b;
* slot b is compared with the others together ("the rest", r): g_b points *out* of body b
  (grad N_i at a particle points towards the node, away from the particles), g_r = sum of the
  others' gradients. The two sides must face each other, unit(g_b) . unit(g_r) <= -1/2: where
  they do not (the front face of a block over the surface of the body it slides on, where
  that body's shape functions reach a cell above its surface), it is not a contact;
* the contact normal is the direction of the stronger of the two mass gradients (the side
  whose surface the node resolves better: the flat surface under a block's corner, not the
  corner), n_b = unit(g_b) or -unit(g_r), the average of the two unit normals when the
  magnitudes tie to 1e-9 (a symmetric contact). Between two slots both use the same normal with
  opposite signs, so the corrections conserve momentum exactly;
* if b approaches, (v_b - v_cm) . n_b > 0, its normal relative velocity is removed and its
  tangential relative velocity reduced by at most ``mu`` times the normal correction (Coulomb;
  it sticks when that is enough). Separating slots are left alone, and components that an
  essential BC constrains are not touched.

Optional effects are passed as ``None`` (compiled out), the basis as a tag of
``pmpm.core.shape.SHAPE_TAGS``, as in :mod:`pmpm.core.kernels.transfer`.
"""
import math

import numba as nb

from pmpm.core.shape import weights
from pmpm.core.kernels.transfer import _external_force, move, strain_increment

__all__ = ["p2g_bodies", "g2p_velocity_bodies", "g2p_kinematics_bodies", "contact_update",
           "N_BODY_FIELDS", "MASS", "MOM", "FORCE", "GRAD", "REMAP", "FACING"]

N_BODY_FIELDS = 9
MASS, MOM, FORCE, GRAD, REMAP = 0, 1, 3, 5, 7

#: two sides are in contact at a node only if their unit mass gradients make an angle of at
#: least 120 degrees (cosine <= -1/2); surfaces meeting at right angles are not in contact
FACING = -0.5
#: mass gradients whose magnitudes differ by less than this (relative) tie
_TIE = 1e-9


@nb.njit(cache=True)
def p2g_bodies(x, m, v, vol, stress, body, slot_of, gravity, load_id, load_w, load_vec,
               B, ox, oy, origin, inv_h, ncx, ncy, shape):
    """:func:`pmpm.core.kernels.transfer.p2g` into each particle's own slot; with the mass and
    momentum (``v`` not None) also the mass gradient sum m_p grad N_i (fields 5, 6)."""
    with_force = stress is not None or gravity is not None or load_id is not None
    for p in range(x.shape[0]):
        s = slot_of[body[p]]
        sx = (x[p, 0] - origin[0]) * inv_h
        sy = (x[p, 1] - origin[1]) * inv_h
        i0, wx, gx = weights(shape, sx, ncx)
        j0, wy, gy = weights(shape, sy, ncy)
        mp = m[p]
        if v is not None:
            mvx = mp * v[p, 0]
            mvy = mp * v[p, 1]
            mg = mp * inv_h
        fx, fy = _external_force(p, m, gravity, load_id, load_w, load_vec)
        if stress is not None:
            # f_int = -V sigma . grad N  (gradient in cell units times 1/h)
            a = -vol[p] * inv_h
            sxx = a * stress[p, 0]
            syy = a * stress[p, 1]
            sxy = a * stress[p, 2]
        for a_ in range(len(wx)):
            ii = i0 + a_ - ox
            for b_ in range(len(wy)):
                jj = j0 + b_ - oy
                w = wx[a_] * wy[b_]
                dnx = gx[a_] * wy[b_]
                dny = wx[a_] * gy[b_]
                if v is not None:
                    B[ii, jj, s, 0] += w * mp
                    B[ii, jj, s, 1] += w * mvx
                    B[ii, jj, s, 2] += w * mvy
                    B[ii, jj, s, 5] += mg * dnx
                    B[ii, jj, s, 6] += mg * dny
                if with_force:
                    fnx = w * fx
                    fny = w * fy
                    if stress is not None:
                        fnx += sxx * dnx + sxy * dny
                        fny += sxy * dnx + syy * dny
                    B[ii, jj, s, 3] += fnx
                    B[ii, jj, s, 4] += fny


@nb.njit(cache=True, inline="always")
def _contact_node(B, i, j, vf, dvf, momentum, mass_cutoff, mu, bc_mask):
    """The contact correction at node (i, j); see the module docstring and contact_update."""
    ns = B.shape[2]
    count = 0
    mtot = 0.0
    px = 0.0
    py = 0.0
    for s in range(ns):
        ms = B[i, j, s, 0]
        if ms > mass_cutoff:
            count += 1
            mtot += ms
            if momentum:
                px += B[i, j, s, vf]
                py += B[i, j, s, vf + 1]
            else:
                px += ms * B[i, j, s, vf]
                py += ms * B[i, j, s, vf + 1]
    if count < 2:
        return 0
    vcx = px / mtot
    vcy = py / mtot
    fix_x = bc_mask[i, j, 0] != 0
    fix_y = bc_mask[i, j, 1] != 0
    corrected = 0
    for b in range(ns):
        mb = B[i, j, b, 0]
        if not mb > mass_cutoff:
            continue
        gbx = B[i, j, b, GRAD]
        gby = B[i, j, b, GRAD + 1]
        grx = 0.0  # the rest's mass gradient
        gry = 0.0
        for c in range(ns):
            if c != b and B[i, j, c, 0] > mass_cutoff:
                grx += B[i, j, c, GRAD]
                gry += B[i, j, c, GRAD + 1]
        gb = math.sqrt(gbx * gbx + gby * gby)
        gr = math.sqrt(grx * grx + gry * gry)
        if not (gb > 0.0 and gr > 0.0):
            continue
        ubx = gbx / gb
        uby = gby / gb
        urx = grx / gr
        ury = gry / gr
        if ubx * urx + uby * ury > FACING:
            continue  # the two sides do not face each other
        if abs(gb - gr) <= _TIE * (gb + gr):
            nx = ubx - urx
            ny = uby - ury
            nn = math.sqrt(nx * nx + ny * ny)
            nx /= nn
            ny /= nn
        elif gb > gr:
            nx = ubx
            ny = uby
        else:
            nx = -urx
            ny = -ury
        vx = B[i, j, b, vf]
        vy = B[i, j, b, vf + 1]
        if momentum:
            vx /= mb
            vy /= mb
        dx = vx - vcx
        dy = vy - vcy
        dn = dx * nx + dy * ny
        if dn > 0.0:  # approaching
            tx = dx - dn * nx
            ty = dy - dn * ny
            cx = -dn * nx
            cy = -dn * ny
            st = math.sqrt(tx * tx + ty * ty)
            if st > 0.0:
                f = min(mu * dn, st) / st
                cx -= f * tx
                cy -= f * ty
            if fix_x:
                cx = 0.0
            if fix_y:
                cy = 0.0
            if momentum:
                B[i, j, b, vf] += mb * cx
                B[i, j, b, vf + 1] += mb * cy
            else:
                B[i, j, b, vf] += cx
                B[i, j, b, vf + 1] += cy
            if dvf >= 0:
                B[i, j, b, dvf] += cx
                B[i, j, b, dvf + 1] += cy
            corrected += 1
    return corrected


@nb.njit(cache=True)
def contact_update(B, vf, dvf, momentum, mass_cutoff, mu, bc_mask, i_lo, i_hi, j_lo, j_hi):
    """Contact correction over window rows [i_lo, i_hi) x [j_lo, j_hi) (see the module
    docstring) of the slot velocities in fields ``vf, vf + 1`` or, with ``momentum``, of the
    momenta there (the velocity being momentum / mass); with ``dvf`` >= 0 the same velocity
    change is added to fields ``dvf, dvf + 1`` (the velocity change FLIP adds to the particles).
    Slots lighter than ``mass_cutoff`` at a node take no part. Returns the number of corrected
    (node, slot) pairs."""
    n = 0
    for i in range(i_lo, i_hi):
        for j in range(j_lo, j_hi):
            n += _contact_node(B, i, j, vf, dvf, momentum, mass_cutoff, mu, bc_mask)
    return n


@nb.njit(cache=True)
def g2p_velocity_bodies(x, m, v, body, slot_of, pic, B, ox, oy, origin, inv_h, ncx, ncy, shape,
                        remap, dx, dt):
    """:func:`pmpm.core.kernels.transfer.g2p_velocity` from each particle's own slot (the MUSL
    re-map goes into fields 7, 8 of that slot; ``dx`` receives the move dt sum N_i v_i).
    Returns the largest speed and the number of non-finite velocities."""
    vmax2 = 0.0
    bad = 0
    flip = 1.0 - pic
    for p in range(x.shape[0]):
        s = slot_of[body[p]]
        sx = (x[p, 0] - origin[0]) * inv_h
        sy = (x[p, 1] - origin[1]) * inv_h
        i0, wx, gx = weights(shape, sx, ncx)
        j0, wy, gy = weights(shape, sy, ncy)
        dvx = 0.0
        dvy = 0.0
        vx = 0.0
        vy = 0.0
        for a_ in range(len(wx)):
            ii = i0 + a_ - ox
            for b_ in range(len(wy)):
                jj = j0 + b_ - oy
                w = wx[a_] * wy[b_]
                vx += w * B[ii, jj, s, 1]
                vy += w * B[ii, jj, s, 2]
                dvx += w * B[ii, jj, s, 3]
                dvy += w * B[ii, jj, s, 4]
        dx[p, 0] = dt * vx
        dx[p, 1] = dt * vy
        nvx = flip * (v[p, 0] + dvx) + pic * vx
        nvy = flip * (v[p, 1] + dvy) + pic * vy
        v[p, 0] = nvx
        v[p, 1] = nvy
        speed2 = nvx * nvx + nvy * nvy
        if speed2 > vmax2:
            vmax2 = speed2
        elif not speed2 < 1e300:  # NaN or inf
            bad += 1
        if remap:
            mvx = m[p] * nvx
            mvy = m[p] * nvy
            for a_ in range(len(wx)):
                ii = i0 + a_ - ox
                for b_ in range(len(wy)):
                    jj = j0 + b_ - oy
                    w = wx[a_] * wy[b_]
                    B[ii, jj, s, 7] += w * mvx
                    B[ii, jj, s, 8] += w * mvy
    return vmax2 ** 0.5, bad


@nb.njit(cache=True)
def g2p_kinematics_bodies(x, m, vol, strain, de, dw, F, vol0, dq, body, slot_of, vel_field, dx, dt,
                          gravity, load_id, load_w, load_vec,
                          B, ox, oy, origin, inv_h, ncx, ncy, shape):
    """:func:`pmpm.core.kernels.transfer.g2p_kinematics` from each particle's own slot: strain
    increment from its velocity field ``vel_field`` (body layout), volume update (and
    ``strain`` when not None; ``F``, ``vol0``, ``dq`` as there), then (``dx`` not None) the move x += dx. Returns the work of the
    external forces over the moves."""
    work = 0.0
    for p in range(x.shape[0]):
        s = slot_of[body[p]]
        sx = (x[p, 0] - origin[0]) * inv_h
        sy = (x[p, 1] - origin[1]) * inv_h
        i0, wx, gx = weights(shape, sx, ncx)
        j0, wy, gy = weights(shape, sy, ncy)
        lxx = 0.0
        lxy = 0.0
        lyx = 0.0
        lyy = 0.0
        for a_ in range(len(wx)):
            ii = i0 + a_ - ox
            for b_ in range(len(wy)):
                jj = j0 + b_ - oy
                if de is not None:
                    dnx = gx[a_] * wy[b_]
                    dny = wx[a_] * gy[b_]
                    gvx = B[ii, jj, s, vel_field]
                    gvy = B[ii, jj, s, vel_field + 1]
                    lxx += gvx * dnx
                    lxy += gvx * dny
                    lyx += gvy * dnx
                    lyy += gvy * dny
        if de is not None:
            strain_increment(p, dt * inv_h, lxx, lxy, lyx, lyy, de, dw, strain, vol, F, vol0, dq)
        if dx is not None:
            work += move(p, x, dx, m, gravity, load_id, load_w, load_vec)
    return work
