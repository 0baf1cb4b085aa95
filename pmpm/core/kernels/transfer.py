"""Particle <-> grid transfers (paper eq. 2, 5, 6).

Every kernel recomputes the shape functions from the start-of-step positions: all transfers in
one step use the same weights (as CB-Geo MPM does), and recomputing is cheaper than storing
16 weights and 32 gradients per particle once the problem leaves the cache.

The particles go in blocks of ``BLOCK``: a block's weights are evaluated together (SIMD, see
pmpm/core/shape.py), then each particle of the block does its scatter or gather from them. The
weight of node (I0[q] + a, J0[q] + b) is WX[a, q] * WY[b, q], its gradient in cell units
(WX[K + a, q] * WY[b, q], WX[a, q] * WY[K + b, q]).

CPDI (``shape`` the tuple (tag, domain, F, escape), pmpm/core/shape.py) has kernels of its own,
chosen by the type of ``shape`` when numba compiles ``p2g``, ``g2p_velocity`` and
``g2p_kinematics`` (the other scenes' machine code is unchanged): a block's four corners are
evaluated as sub-points of the basis, and each particle scatters m/4, m v/4 and
f_c = -V sigma g_c + f_ext/4 at each corner with the corner's weights, gathers the mean of the
corners' velocities and L = sum_c v(x_c) (x) g_c; the corners' weights are merged onto one node
box per particle first where they fit one (see the CPDI section below). A corner whose support leaves the rank's
window is dropped (nothing is written outside it) and counted in ``escape``.
"""
import math

import numba as nb
import numpy as np

from numba.extending import overload

from pmpm.core.shape import (BLOCK, block_coordinates, block_domain, block_weights, cpdi_boxes, cpdi_corners,
                             is_cpdi, stencil)

__all__ = ["p2g", "g2p_velocity", "g2p_kinematics"]


@nb.njit(cache=True, inline="always")
def _external_force(p, m, gravity, load_id, load_w, load_vec):
    """Body force m g plus this particle's share of its load set's current total force."""
    fx = 0.0
    fy = 0.0
    if gravity is not None:
        fx += m[p] * gravity[0]
        fy += m[p] * gravity[1]
    if load_id is not None:
        k = load_id[p]
        if k >= 0:
            fx += load_w[p] * load_vec[k, 0]
            fy += load_w[p] * load_vec[k, 1]
    return fx, fy


@nb.njit(cache=True, inline="always")
def polar_angle(fxx, fxy, fyx, fyy):
    """Angle of the rotation R of the polar decomposition F = R U of a 2x2 F with det F > 0:
    F11 + F22 = cos(theta) tr U and F21 - F12 = sin(theta) tr U, tr U > 0."""
    return math.atan2(fyx - fxy, fxx + fyy)


@nb.njit(cache=True, inline="always")
def strain_increment(p, c, lxx, lxy, lyx, lyy, de, dw, strain, vol, F, vol0, dq):
    """Particle p's strain increment c L (c = dt / h, L the velocity gradient sums in cell
    units) into ``de`` (not None: a caller that keeps the increment in registers leaves it
    out), its spin into ``dw`` (not None), ``strain`` (not None) and volume.

    With ``F`` (N, 5: Fxx, Fxy, Fyx, Fyy, Fzz) not None the deformation gradient is advanced
    by the same velocity gradient, F <- (I + dt L) F (Fzz is the material's: plane stress
    thickness stretch), and the volume is ``vol0`` det F (in-plane det: the volume is the area
    times the initial thickness, see docs/deformation_gradient.md); ``dq`` (N, 2; not None)
    receives the cosine and sine of the increment of the polar rotation angle of F over the
    step (Green-Naghdi rate).
    Without F the volume follows the trace of the increment, vol *= 1 + tr(de)."""
    dexx = c * lxx
    deyy = c * lyy
    dgxy = c * (lxy + lyx)
    if de is not None:
        de[p, 0] = dexx
        de[p, 1] = deyy
        de[p, 2] = dgxy
    if dw is not None:
        dw[p] = 0.5 * c * (lyx - lxy)
    if strain is not None:
        strain[p, 0] += dexx
        strain[p, 1] += deyy
        strain[p, 2] += dgxy
    if F is not None:
        fxx = F[p, 0]
        fxy = F[p, 1]
        fyx = F[p, 2]
        fyy = F[p, 3]
        nxx = fxx + dexx * fxx + c * lxy * fyx
        nxy = fxy + dexx * fxy + c * lxy * fyy
        nyx = fyx + c * lyx * fxx + deyy * fyx
        nyy = fyy + c * lyx * fxy + deyy * fyy
        F[p, 0] = nxx
        F[p, 1] = nxy
        F[p, 2] = nyx
        F[p, 3] = nyy
        vol[p] = vol0[p] * (nxx * nyy - nxy * nyx)
        if dq is not None:
            # the rotation from polar_angle(old) to polar_angle(new) without trigonometry: the
            # vectors (F11 + F22, F21 - F12) of the two point along their R (tr U > 0), so the
            # cosine and sine of the angle between them are their dot and cross products over
            # the product of their lengths
            ox = fxx + fyy
            oy = fyx - fxy
            qx = nxx + nyy
            qy = nyx - nxy
            n2 = (ox * ox + oy * oy) * (qx * qx + qy * qy)
            # n2 = 0 only when an F is no longer a rotation times a stretch (det F <= 0): NaN
            # then, and the step's F check stops the run
            r = 1.0 / math.sqrt(n2) if n2 > 0.0 else math.nan
            dq[p, 0] = (ox * qx + oy * qy) * r
            dq[p, 1] = (ox * qy - oy * qx) * r
    else:
        vol[p] *= 1.0 + dexx + deyy


@nb.njit(cache=True, inline="always")
def move(p, x, dx, m, gravity, load_id, load_w, load_vec):
    """x += dx for particle p; returns the work of its external force over the move."""
    ux = dx[p, 0]
    uy = dx[p, 1]
    x[p, 0] += ux
    x[p, 1] += uy
    fx, fy = _external_force(p, m, gravity, load_id, load_w, load_vec)
    return fx * ux + fy * uy


@nb.njit(cache=True, inline="always")
def _buffers(shape):
    """Per-block scratch: coordinates and domain half-lengths (GIMP), first nodes and
    weights/derivatives along x and y."""
    k2 = 2 * stencil(shape)
    return (np.empty((2, BLOCK)), np.empty(BLOCK, np.int64), np.empty(BLOCK, np.int64),
            np.empty((k2, BLOCK)), np.empty((k2, BLOCK)))


@nb.njit(cache=True, inline="always")
def gather2(G, f, q, K, I0, J0, WX, WY, ox, oy):
    """(sum_i N_i G_i[f], sum_i N_i G_i[f + 1]) over particle q's stencil (its block weights):
    the gather loop of one grid vector (XPIC's smoothing pass, MLS-MPM's linear velocity)."""
    ux = 0.0
    uy = 0.0
    for a in range(K):
        ii = I0[q] + a - ox
        wa = WX[a, q]
        for b in range(K):
            jj = J0[q] + b - oy
            w = wa * WY[b, q]
            ux += w * G[ii, jj, f]
            uy += w * G[ii, jj, f + 1]
    return ux, uy


@nb.njit(cache=True, inline="always")
def gather4(G, f, g, q, K, I0, J0, WX, WY, ox, oy):
    """The gather of two grid vectors in one loop: sum_i N_i G_i[f, f + 1] and
    sum_i N_i G_i[g, g + 1] (FLIP: the velocity and its change)."""
    vx = 0.0
    vy = 0.0
    dvx = 0.0
    dvy = 0.0
    for a in range(K):
        ii = I0[q] + a - ox
        wa = WX[a, q]
        for b in range(K):
            jj = J0[q] + b - oy
            w = wa * WY[b, q]
            vx += w * G[ii, jj, f]
            vy += w * G[ii, jj, f + 1]
            dvx += w * G[ii, jj, g]
            dvy += w * G[ii, jj, g + 1]
    return vx, vy, dvx, dvy


@nb.njit(cache=True, inline="always")
def gather_gradient(G, f, q, K, I0, J0, WX, WY, ox, oy):
    """L = sum_i v_i (x) grad N_i in cell units (lxx, lxy, lyx, lyy), v the grid vector in
    fields f, f + 1: the velocity gradient of the strain increment."""
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
            gvx = G[ii, jj, f]
            gvy = G[ii, jj, f + 1]
            lxx += gvx * dnx
            lxy += gvx * dny
            lyx += gvy * dnx
            lyy += gvy * dny
    return lxx, lxy, lyx, lyy


@nb.njit(cache=True, inline="always")
def scatter2(G, f, q, K, I0, J0, WX, WY, ox, oy, ax, ay, affine):
    """G_i[f] += N_i ax, G_i[f + 1] += N_i ay over particle q's stencil: the scatter loop of a
    particle's vector (the MUSL re-map, XPIC's smoothing pass). With ``affine`` (kxx, kxy,
    kyx, kyy, sx, sy) not None the vector has an affine part: a + k (x_i - x_p), k per cell of
    offset, (sx, sy) the particle's position in cells (the APIC re-map)."""
    i0 = I0[q]   # in registers: the loop writes G, which the compiler cannot tell from I0
    j0 = J0[q]
    for a in range(K):
        ii = i0 + a - ox
        wa = WX[a, q]
        for b in range(K):
            jj = j0 + b - oy
            w = wa * WY[b, q]
            if affine is None:
                G[ii, jj, f] += w * ax
                G[ii, jj, f + 1] += w * ay
            else:
                ddx = i0 + a - affine[4]   # x_i - x_p in cells
                ddy = j0 + b - affine[5]
                G[ii, jj, f] += w * (ax + affine[0] * ddx + affine[1] * ddy)
                G[ii, jj, f + 1] += w * (ay + affine[2] * ddx + affine[3] * ddy)


@nb.njit(cache=True, inline="always")
def scatter_p2g(G, q, K, I0, J0, WX, WY, ox, oy, mass, mp, mvx, mvy, affine,
                force, fx, fy, stress, sxx, syy, sxy, mls):
    """Particle q's particle-to-grid scatter over its stencil, the one loop of the point
    kernels (FLIP's, APIC's, MLS-MPM's): with ``mass``, m N_i into field 0 and the momentum
    N_i (m v + k (x_i - x_p)) into 1, 2 (``affine`` as in :func:`scatter2`, None: no affine
    part); with ``force``, N_i f_ext + (sxx, sxy; sxy, syy) g_i into 3, 4 (``stress``: with
    the stress term), g_i the gradient grad N_i in cell units. With ``mls`` (axx, axy, ayx,
    ayy) not None (and ``affine`` given) the stress term is MLS-MPM's, N_i A (x_i - x_p) with
    A = (sxx, sxy; sxy, syy) D^-1 computed once per particle (the force in the form of the
    affine momentum: g_i = N_i D^-1 (x_i - x_p))."""
    i0 = I0[q]   # in registers: the loop writes G, which the compiler cannot tell from I0
    j0 = J0[q]
    for a in range(K):
        ii = i0 + a - ox
        wa = WX[a, q]
        ga = WX[K + a, q]
        for b in range(K):
            jj = j0 + b - oy
            wb = WY[b, q]
            w = wa * wb
            if mass:
                G[ii, jj, 0] += w * mp
                if affine is None:
                    G[ii, jj, 1] += w * mvx
                    G[ii, jj, 2] += w * mvy
                else:
                    ddx = i0 + a - affine[4]
                    ddy = j0 + b - affine[5]
                    G[ii, jj, 1] += w * (mvx + affine[0] * ddx + affine[1] * ddy)
                    G[ii, jj, 2] += w * (mvy + affine[2] * ddx + affine[3] * ddy)
            if force:
                if mls is None:
                    fnx = w * fx
                    fny = w * fy
                    if stress:
                        dnx = ga * wb
                        dny = wa * WY[K + b, q]
                        fnx += sxx * dnx + sxy * dny
                        fny += sxy * dnx + syy * dny
                else:
                    ex = i0 + a - affine[4]
                    ey = j0 + b - affine[5]
                    fnx = w * (fx + mls[0] * ex + mls[1] * ey)
                    fny = w * (fy + mls[2] * ex + mls[3] * ey)
                G[ii, jj, 3] += fnx
                G[ii, jj, 4] += fny


@nb.njit(cache=True, inline="always")
def _block_weights(x, p0, nq, origin, inv_h, ncx, ncy, shape, S, I0, J0, WX, WY):
    """Weights of particles p0 .. p0 + nq - 1 into I0, WX (x axis) and J0, WY (y axis);
    S[0] takes the coordinates, S[1] the domain half-lengths (GIMP only)."""
    s, L = S[0], S[1]
    block_coordinates(x, p0, nq, 0, origin[0], inv_h, s)
    block_domain(shape, p0, nq, 0, L)
    block_weights(shape, s, L, nq, ncx, I0, WX)
    block_coordinates(x, p0, nq, 1, origin[1], inv_h, s)
    block_domain(shape, p0, nq, 1, L)
    block_weights(shape, s, L, nq, ncy, J0, WY)


@nb.njit(cache=True, inline="always")
def block_start(x, p0, origin, inv_h, ncx, ncy, shape, B):
    """The block of particles from p0 (``B`` from :func:`_buffers`): its weights evaluated;
    returns its particle count."""
    nq = min(BLOCK, x.shape[0] - p0)
    _block_weights(x, p0, nq, origin, inv_h, ncx, ncy, shape, B[0], B[1], B[2], B[3], B[4])
    return nq


@nb.njit(cache=True, inline="always")
def internal_force_stress(p, vol, stress, inv_h):
    """-V sigma / h of particle p (xx, yy, xy): times a gradient in cell units, its force."""
    c = -vol[p] * inv_h
    return c * stress[p, 0], c * stress[p, 1], c * stress[p, 2]


@nb.njit(cache=True, inline="always")
def particle_forces(p, m, vol, stress, gravity, load_id, load_w, load_vec, inv_h):
    """Particle p's external force and its -V sigma / h: (fx, fy, sxx, syy, sxy), the stress
    part zero when ``stress`` is None (a pass without internal forces)."""
    fx, fy = _external_force(p, m, gravity, load_id, load_w, load_vec)
    sxx = 0.0
    syy = 0.0
    sxy = 0.0
    if stress is not None:
        # f_int = -V sigma . grad N  (gradient in cell units times 1/h)
        sxx, syy, sxy = internal_force_stress(p, vol, stress, inv_h)
    return fx, fy, sxx, syy, sxy


@nb.njit(cache=True, inline="always")
def block_buffers(shape):
    """(K, B, I0, J0, WX, WY): the stencil width and the per-block scratch of :func:`_buffers`
    with its first nodes and weights unpacked."""
    B = _buffers(shape)
    return stencil(shape), B, B[1], B[2], B[3], B[4]


@nb.njit(cache=True, inline="always")
def speed_check(vx, vy, vmax2, bad):
    """The running largest squared speed and count of non-finite velocities with (vx, vy)."""
    speed2 = vx * vx + vy * vy
    if speed2 > vmax2:
        vmax2 = speed2
    elif not speed2 < 1e300:  # NaN or inf
        bad += 1
    return vmax2, bad


def _p2g_point(x, m, v, vol, stress, gravity, load_id, load_w, load_vec,
               G, ox, oy, origin, inv_h, ncx, ncy, shape):
    """Scatter mass and momentum (``v`` not None), internal force (``stress`` not None) and
    external force (``gravity``/``load_id`` not None) into the grid window ``G``."""
    with_force = stress is not None or gravity is not None or load_id is not None
    K, B, I0, J0, WX, WY = block_buffers(shape)
    for p0 in range(0, x.shape[0], BLOCK):
        nq = block_start(x, p0, origin, inv_h, ncx, ncy, shape, B)
        for q in range(nq):
            p = p0 + q
            mp = m[p]
            mvx = 0.0
            mvy = 0.0
            if v is not None:
                mvx = mp * v[p, 0]
                mvy = mp * v[p, 1]
            fx, fy, sxx, syy, sxy = particle_forces(p, m, vol, stress, gravity, load_id, load_w, load_vec, inv_h)
            scatter_p2g(G, q, K, I0, J0, WX, WY, ox, oy, v is not None, mp, mvx, mvy, None,
                        with_force, fx, fy, stress is not None, sxx, syy, sxy, None)


def _g2p_velocity_point(x, m, v, pic, G, ox, oy, origin, inv_h, ncx, ncy, shape, remap, dx, dt):
    """Update particle velocities from the grid (FLIP with a PIC blend, paper eq. 5) and, when
    ``remap`` is True, scatter the new particle momentum into fields 5, 6 (MUSL, paper eq. 6).
    ``dx`` (N, 2) receives each particle's move dt sum N_i v_i (eq. 5); it is applied later,
    after the strain increment, so every transfer of the step uses the same weights.

    Returns the largest particle speed (for the next CFL time step) and the number of
    particles whose new velocity is not finite."""
    vmax2 = 0.0
    bad = 0
    flip = 1.0 - pic
    K, B, I0, J0, WX, WY = block_buffers(shape)
    for p0 in range(0, x.shape[0], BLOCK):
        nq = block_start(x, p0, origin, inv_h, ncx, ncy, shape, B)
        for q in range(nq):
            p = p0 + q
            vx, vy, dvx, dvy = gather4(G, 1, 3, q, K, I0, J0, WX, WY, ox, oy)
            dx[p, 0] = dt * vx
            dx[p, 1] = dt * vy
            nvx = flip * (v[p, 0] + dvx) + pic * vx
            nvy = flip * (v[p, 1] + dvy) + pic * vy
            v[p, 0] = nvx
            v[p, 1] = nvy
            vmax2, bad = speed_check(nvx, nvy, vmax2, bad)
            if remap:
                scatter2(G, 5, q, K, I0, J0, WX, WY, ox, oy, m[p] * nvx, m[p] * nvy, None)
    return vmax2 ** 0.5, bad


def _g2p_kinematics_point(x, m, vol, strain, de, dw, F, vol0, dq, vel_field, dx, dt,
                          gravity, load_id, load_w, load_vec,
                          G, ox, oy, origin, inv_h, ncx, ncy, shape):
    """Strain increment from the grid velocity in ``vel_field`` (paper eq. 6), volume update,
    and (``dx`` not None) the position update x += dx computed by g2p_velocity (eq. 5).

    ``de`` (N, 3) receives the strain increment when not None (``vol`` and, when kept,
    ``strain`` are updated with it); ``dw`` (N,) the spin increment when not None (Jaumann
    rate); ``F``, ``vol0``, ``dq``: the deformation gradient, see :func:`strain_increment`.
    Returns the work of the external forces over the moves."""
    work = 0.0
    K, B, I0, J0, WX, WY = block_buffers(shape)
    n = x.shape[0]
    for p0 in range(0, n, BLOCK):
        nq = min(BLOCK, n - p0)
        if de is not None:
            block_start(x, p0, origin, inv_h, ncx, ncy, shape, B)
        for q in range(nq):
            p = p0 + q
            if de is not None:
                lxx, lxy, lyx, lyy = gather_gradient(G, vel_field, q, K, I0, J0, WX, WY, ox, oy)
                strain_increment(p, dt * inv_h, lxx, lxy, lyx, lyy, de, dw, strain, vol, F, vol0, dq)
            if dx is not None:
                work += move(p, x, dx, m, gravity, load_id, load_w, load_vec)
    return work


# -- CPDI: four corners per particle, merged onto one node box ---------------------------------
#
# The kernels evaluate a block's corners and their node boxes (``cpdi_boxes``,
# pmpm/core/shape.py), then visit each particle's (K + 1)^2 box nodes once: with n_c = N_i(x_c)
# the corners' basis values on node i, the particle's weight is w_i = (n_1 + .. + n_4) / 4 and
# its gradient (cell units) (n_1 - n_3) a/V + (n_2 - n_4) b/V (g_3 = -g_1, g_4 = -g_2): 25 grid
# visits per transfer with cubic B-splines instead of 64. The few particles that do not fit a
# box (boundary-modified weights near a grid edge, domains stretched past about a cell, a box
# leaving the window) take the per-corner loops, for which the block's corners' weights are
# evaluated with their first nodes (``block_weights``) only when the block holds one.

@nb.njit(cache=True, inline="always")
def _cpdi_buffers(tag):
    """Per-block scratch of CPDI: corner coordinates C[axis, c, q], the gradient vectors
    GV[0..3, q] = (ax, ay, bx, by) of each particle; the node boxes' first nodes BI[q], BJ[q],
    the corners' weights on them UX[c, a, q], UY[c, b, q] (a, b = 0 .. K) and whether particle
    q fits its box, OK[q] (from the per-axis OKX[q], OKY[q]); for the per-corner path, the first nodes I0[c, q], J0[c, q] and
    weights/derivatives WX[c], WY[c] of each corner."""
    K = stencil(tag)
    return (np.empty((2, 4, BLOCK)), np.empty((4, BLOCK)),
            np.zeros(BLOCK, np.int64), np.zeros(BLOCK, np.int64),
            np.zeros((4, K + 1, BLOCK)), np.zeros((4, K + 1, BLOCK)), np.zeros(BLOCK, np.bool_),
            np.zeros(BLOCK), np.zeros(BLOCK),
            np.empty((4, BLOCK), np.int64), np.empty((4, BLOCK), np.int64),
            np.empty((4, 2 * K, BLOCK)), np.empty((4, 2 * K, BLOCK)))


@nb.njit(cache=True, inline="always")
def _cpdi_block(x, p0, nq, origin, inv_h, ncx, ncy, shape, ox, oy, nwx, nwy, B):
    """Corners, gradient vectors and node boxes of particles p0 .. p0 + nq - 1 into the buffers
    ``B`` (see ``_cpdi_buffers``); when one of them does not fit its box, also every corner's
    weights for the per-corner path. There a corner whose support leaves the window (nwx x nwy
    nodes from (ox, oy)) gets zero weights on nodes inside it and is counted in ``escape``
    (shape[3]: [count, first particle]); a particle that fits its box has none such."""
    C, GV, BI, BJ, UX, UY, OK, OKX, OKY, I0, J0, WX, WY = B
    tag, domain, F, escape = shape[0], shape[1], shape[2], shape[3]
    for q in range(nq):
        p = p0 + q
        cx, cy, ax, ay, bx, by = cpdi_corners(domain, F, p, (x[p, 0] - origin[0]) * inv_h,
                                              (x[p, 1] - origin[1]) * inv_h, ncx, ncy)
        for c in range(4):
            C[0, c, q] = cx[c]
            C[1, c, q] = cy[c]
        GV[0, q] = ax
        GV[1, q] = ay
        GV[2, q] = bx
        GV[3, q] = by
    cpdi_boxes(tag, C[0], nq, ncx, ox, nwx, BI, UX, OKX)
    cpdi_boxes(tag, C[1], nq, ncy, oy, nwy, BJ, UY, OKY)
    every = True
    for q in range(nq):
        fits = OKX[q] * OKY[q] > 0.0
        OK[q] = fits
        every &= fits
    if every:
        return
    for c in range(4):
        # the basis's block weights take the corners as points (their L argument is unused)
        block_weights(tag, C[0, c], C[0, c], nq, ncx, I0[c], WX[c])
        block_weights(tag, C[1, c], C[1, c], nq, ncy, J0[c], WY[c])
    K = stencil(tag)
    for c in range(4):
        for q in range(nq):
            if I0[c, q] < ox or I0[c, q] + K > ox + nwx or J0[c, q] < oy or J0[c, q] + K > oy + nwy:
                I0[c, q] = ox
                J0[c, q] = oy
                for k in range(2 * K):
                    WX[c, k, q] = 0.0
                    WY[c, k, q] = 0.0
                escape[0] += 1
                if escape[1] < 0:
                    escape[1] = p0 + q


@nb.njit(cache=True, inline="always")
def _corner_vector(GV, q, c):
    """g_c of particle q of the block: g_1 = a/V, g_2 = b/V, g_3 = -g_1, g_4 = -g_2 (c = 0..3)."""
    sign = 1.0 if c < 2 else -1.0
    k = 2 * (c % 2)
    return sign * GV[k, q], sign * GV[k + 1, q]


# The per-corner path of a particle that does not fit its box: separate functions, not inlined,
# so that the box loops above compile as tight as the point kernels' (inlined, these made the
# box path up to twice as slow).

@nb.njit(cache=True)
def _p2g_corners(G, q, K, B, ox, oy, mp, mvx, mvy, fx, fy, sxx, syy, sxy, mass, force):
    """Particle q's p2g at its four corners: m/4, m v/4 (``mass``) and
    f_c = -V sigma g_c + f_ext / 4 (``force``) on each corner's nodes."""
    GV, I0, J0, WX, WY = B[1], B[9], B[10], B[11], B[12]
    for c in range(4):
        gx, gy = _corner_vector(GV, q, c)
        fcx = 0.25 * fx + sxx * gx + sxy * gy
        fcy = 0.25 * fy + sxy * gx + syy * gy
        for a in range(K):
            ii = I0[c, q] + a - ox
            wa = WX[c, a, q]
            for b in range(K):
                jj = J0[c, q] + b - oy
                w = wa * WY[c, b, q]
                if mass:
                    G[ii, jj, 0] += 0.25 * w * mp
                    G[ii, jj, 1] += 0.25 * w * mvx
                    G[ii, jj, 2] += 0.25 * w * mvy
                if force:
                    G[ii, jj, 3] += w * fcx
                    G[ii, jj, 4] += w * fcy


@nb.njit(cache=True)
def _gather_corners(G, q, K, B, ox, oy):
    """The mean over particle q's corners of the grid's velocity (fields 1, 2) and change (3, 4)."""
    I0, J0, WX, WY = B[9], B[10], B[11], B[12]
    vx = 0.0
    vy = 0.0
    dvx = 0.0
    dvy = 0.0
    for c in range(4):
        for a in range(K):
            ii = I0[c, q] + a - ox
            wa = WX[c, a, q]
            for b in range(K):
                jj = J0[c, q] + b - oy
                w = wa * WY[c, b, q]
                vx += w * G[ii, jj, 1]
                vy += w * G[ii, jj, 2]
                dvx += w * G[ii, jj, 3]
                dvy += w * G[ii, jj, 4]
    return 0.25 * vx, 0.25 * vy, 0.25 * dvx, 0.25 * dvy


@nb.njit(cache=True)
def _scatter_corners(G, k, q, K, B, ox, oy, fx, fy):
    """G[i, k] += fx / 4 and G[i, k + 1] += fy / 4 with each corner's weights of particle q."""
    I0, J0, WX, WY = B[9], B[10], B[11], B[12]
    fx *= 0.25
    fy *= 0.25
    for c in range(4):
        for a in range(K):
            ii = I0[c, q] + a - ox
            wa = WX[c, a, q]
            for b in range(K):
                jj = J0[c, q] + b - oy
                w = wa * WY[c, b, q]
                G[ii, jj, k] += w * fx
                G[ii, jj, k + 1] += w * fy


@nb.njit(cache=True)
def _gradient_corners(G, k, q, K, B, ox, oy):
    """L = sum_c v(x_c) (x) g_c of particle q, v the grid field (k, k + 1)."""
    GV, I0, J0, WX, WY = B[1], B[9], B[10], B[11], B[12]
    lxx = 0.0
    lxy = 0.0
    lyx = 0.0
    lyy = 0.0
    for c in range(4):
        gx, gy = _corner_vector(GV, q, c)
        ux = 0.0   # v(x_c), the corner's interpolated velocity
        uy = 0.0
        for a in range(K):
            ii = I0[c, q] + a - ox
            wa = WX[c, a, q]
            for b in range(K):
                jj = J0[c, q] + b - oy
                w = wa * WY[c, b, q]
                ux += w * G[ii, jj, k]
                uy += w * G[ii, jj, k + 1]
        lxx += ux * gx
        lxy += ux * gy
        lyx += uy * gx
        lyy += uy * gy
    return lxx, lxy, lyx, lyy


# The box loops, one function per kernel, called with the box's node counts (K or K + 1 per
# axis) as constants: each of the four cases compiles with its loops unrolled (with the counts
# read from the particle the loops stay rolled: measured 3-5% of each CPDI transfer). The
# four-way branch is written out in each dispatcher rather than shared: a shared one would take
# the loop as a function argument, whose numba type embeds its address and defeats the disk
# cache (docs/performance.md, "What changed").

@nb.njit(cache=True, inline="always")
def _box_cases(okx, oky, K):
    """The box's node counts along x and y from ``cpdi_boxes``' ok flags (1.0 or 2.0)."""
    return K - 1 + int(okx), K - 1 + int(oky)


@nb.njit(cache=True, inline="always")
def _box_p2g_loop(G, i0, j0, q, UX, UY, NA, NB, mass, force, mp, mvx, mvy, fx, fy, tax, tay, tbx, tby):
    for a in range(NA):
        u0, u1, u2, u3 = UX[0, a, q], UX[1, a, q], UX[2, a, q], UX[3, a, q]
        for b in range(NB):
            n0 = u0 * UY[0, b, q]
            n1 = u1 * UY[1, b, q]
            n2 = u2 * UY[2, b, q]
            n3 = u3 * UY[3, b, q]
            w = 0.25 * ((n0 + n1) + (n2 + n3))
            ii = i0 + a
            jj = j0 + b
            if mass:
                G[ii, jj, 0] += w * mp
                G[ii, jj, 1] += w * mvx
                G[ii, jj, 2] += w * mvy
            if force:
                d0 = n0 - n2
                d1 = n1 - n3
                G[ii, jj, 3] += w * fx + d0 * tax + d1 * tbx
                G[ii, jj, 4] += w * fy + d0 * tay + d1 * tby


@nb.njit(cache=True, inline="always")
def _box_p2g(G, i0, j0, q, UX, UY, K, okx, oky, mass, force, mp, mvx, mvy, fx, fy, tax, tay, tbx, tby):
    """Scatter m w_i, m v w_i and f_ext w_i - V sigma grad w_i over particle q's node box."""
    na, nb_ = _box_cases(okx, oky, K)
    if na == K:
        if nb_ == K:
            _box_p2g_loop(G, i0, j0, q, UX, UY, K, K, mass, force, mp, mvx, mvy, fx, fy, tax, tay, tbx, tby)
        else:
            _box_p2g_loop(G, i0, j0, q, UX, UY, K, K + 1, mass, force, mp, mvx, mvy, fx, fy, tax, tay, tbx, tby)
    elif nb_ == K:
        _box_p2g_loop(G, i0, j0, q, UX, UY, K + 1, K, mass, force, mp, mvx, mvy, fx, fy, tax, tay, tbx, tby)
    else:
        _box_p2g_loop(G, i0, j0, q, UX, UY, K + 1, K + 1, mass, force, mp, mvx, mvy, fx, fy, tax, tay, tbx, tby)


@nb.njit(cache=True, inline="always")
def _box_gather_loop(G, i0, j0, q, UX, UY, NA, NB, WB):
    vx = 0.0
    vy = 0.0
    dvx = 0.0
    dvy = 0.0
    for a in range(NA):
        u0, u1, u2, u3 = UX[0, a, q], UX[1, a, q], UX[2, a, q], UX[3, a, q]
        for b in range(NB):
            w = (u0 * UY[0, b, q] + u1 * UY[1, b, q]) + (u2 * UY[2, b, q] + u3 * UY[3, b, q])
            WB[a, b] = w   # for the re-map
            ii = i0 + a
            jj = j0 + b
            vx += w * G[ii, jj, 1]
            vy += w * G[ii, jj, 2]
            dvx += w * G[ii, jj, 3]
            dvy += w * G[ii, jj, 4]
    return 0.25 * vx, 0.25 * vy, 0.25 * dvx, 0.25 * dvy


@nb.njit(cache=True, inline="always")
def _box_gather(G, i0, j0, q, UX, UY, K, okx, oky, WB):
    """The grid velocity (fields 1, 2) and its change (3, 4) at particle q, over its node box;
    its box weights (times 4) into ``WB``."""
    na, nb_ = _box_cases(okx, oky, K)
    if na == K:
        if nb_ == K:
            return _box_gather_loop(G, i0, j0, q, UX, UY, K, K, WB)
        return _box_gather_loop(G, i0, j0, q, UX, UY, K, K + 1, WB)
    if nb_ == K:
        return _box_gather_loop(G, i0, j0, q, UX, UY, K + 1, K, WB)
    return _box_gather_loop(G, i0, j0, q, UX, UY, K + 1, K + 1, WB)


@nb.njit(cache=True, inline="always")
def _box_remap_loop(G, i0, j0, NA, NB, WB, mvx, mvy):
    for a in range(NA):
        for b in range(NB):
            w = 0.25 * WB[a, b]
            G[i0 + a, j0 + b, 5] += w * mvx
            G[i0 + a, j0 + b, 6] += w * mvy


@nb.njit(cache=True, inline="always")
def _box_remap(G, i0, j0, K, okx, oky, WB, mvx, mvy):
    """The MUSL re-map: m v w_i into fields 5, 6 over the box, with the gather's weights."""
    na, nb_ = _box_cases(okx, oky, K)
    if na == K:
        if nb_ == K:
            _box_remap_loop(G, i0, j0, K, K, WB, mvx, mvy)
        else:
            _box_remap_loop(G, i0, j0, K, K + 1, WB, mvx, mvy)
    elif nb_ == K:
        _box_remap_loop(G, i0, j0, K + 1, K, WB, mvx, mvy)
    else:
        _box_remap_loop(G, i0, j0, K + 1, K + 1, WB, mvx, mvy)


@nb.njit(cache=True, inline="always")
def _box_gradient_loop(G, i0, j0, q, UX, UY, NA, NB, k):
    xa = 0.0
    xb = 0.0
    ya = 0.0
    yb = 0.0
    for a in range(NA):
        u0, u1, u2, u3 = UX[0, a, q], UX[1, a, q], UX[2, a, q], UX[3, a, q]
        for b in range(NB):
            d0 = u0 * UY[0, b, q] - u2 * UY[2, b, q]
            d1 = u1 * UY[1, b, q] - u3 * UY[3, b, q]
            gvx = G[i0 + a, j0 + b, k]
            gvy = G[i0 + a, j0 + b, k + 1]
            xa += gvx * d0
            xb += gvx * d1
            ya += gvy * d0
            yb += gvy * d1
    return xa, xb, ya, yb


@nb.njit(cache=True, inline="always")
def _box_gradient(G, i0, j0, q, UX, UY, K, okx, oky, k):
    """sum_i v_i (n_1 - n_3) and sum_i v_i (n_2 - n_4) over the box (v: fields k, k + 1):
    (xa, xb, ya, yb), the x and y components of the two sums."""
    na, nb_ = _box_cases(okx, oky, K)
    if na == K:
        if nb_ == K:
            return _box_gradient_loop(G, i0, j0, q, UX, UY, K, K, k)
        return _box_gradient_loop(G, i0, j0, q, UX, UY, K, K + 1, k)
    if nb_ == K:
        return _box_gradient_loop(G, i0, j0, q, UX, UY, K + 1, K, k)
    return _box_gradient_loop(G, i0, j0, q, UX, UY, K + 1, K + 1, k)


def _p2g_cpdi(x, m, v, vol, stress, gravity, load_id, load_w, load_vec,
              G, ox, oy, origin, inv_h, ncx, ncy, shape):
    """CPDI ``p2g``: mass m w_i, momentum m v w_i and force f_ext w_i - V sigma grad w_i on the
    particle's node box (per corner, as the paper writes it: m/4, m v/4 and
    f_c = -V sigma g_c + f_ext / 4 at each corner's nodes)."""
    with_force = stress is not None or gravity is not None or load_id is not None
    tag = shape[0]
    K = stencil(tag)
    B = _cpdi_buffers(tag)
    GV, BI, BJ, UX, UY, OK, OKX, OKY = B[1], B[2], B[3], B[4], B[5], B[6], B[7], B[8]
    nwx, nwy = G.shape[0], G.shape[1]
    n = x.shape[0]
    for p0 in range(0, n, BLOCK):
        nq = min(BLOCK, n - p0)
        _cpdi_block(x, p0, nq, origin, inv_h, ncx, ncy, shape, ox, oy, nwx, nwy, B)
        for q in range(nq):
            p = p0 + q
            mp = m[p]
            mvx = 0.0
            mvy = 0.0
            if v is not None:
                mvx = mp * v[p, 0]
                mvy = mp * v[p, 1]
            fx, fy = _external_force(p, m, gravity, load_id, load_w, load_vec)
            c0 = 0.0
            sxx = 0.0
            syy = 0.0
            sxy = 0.0
            if stress is not None:
                c0 = -vol[p] * inv_h   # g_c in 1/cell times 1/h
                sxx = c0 * stress[p, 0]
                syy = c0 * stress[p, 1]
                sxy = c0 * stress[p, 2]
            if OK[q]:
                # -V sigma grad w_i = (n_1 - n_3) (-V sigma a/V) + (n_2 - n_4) (-V sigma b/V)
                ax, ay, bx, by = GV[0, q], GV[1, q], GV[2, q], GV[3, q]
                tax = sxx * ax + sxy * ay
                tay = sxy * ax + syy * ay
                tbx = sxx * bx + sxy * by
                tby = sxy * bx + syy * by
                _box_p2g(G, BI[q] - ox, BJ[q] - oy, q, UX, UY, K, OKX[q], OKY[q], v is not None,
                         with_force, mp, mvx, mvy, fx, fy, tax, tay, tbx, tby)
                continue
            _p2g_corners(G, q, K, B, ox, oy, mp, mvx, mvy, fx, fy, sxx, syy, sxy,
                         v is not None, with_force)


def _g2p_velocity_cpdi(x, m, v, pic, G, ox, oy, origin, inv_h, ncx, ncy, shape, remap, dx, dt):
    """CPDI ``g2p_velocity``: the mean of the corners' grid velocities (and changes), gathered
    over the particle's node box; the MUSL re-map scatters m v w_i on it."""
    vmax2 = 0.0
    bad = 0
    flip = 1.0 - pic
    tag = shape[0]
    K = stencil(tag)
    B = _cpdi_buffers(tag)
    BI, BJ, UX, UY, OK, OKX, OKY = B[2], B[3], B[4], B[5], B[6], B[7], B[8]
    WB = np.empty((K + 1, K + 1))   # a particle's box weights (times 4)
    nwx, nwy = G.shape[0], G.shape[1]
    n = x.shape[0]
    for p0 in range(0, n, BLOCK):
        nq = min(BLOCK, n - p0)
        _cpdi_block(x, p0, nq, origin, inv_h, ncx, ncy, shape, ox, oy, nwx, nwy, B)
        for q in range(nq):
            p = p0 + q
            if OK[q]:
                vx, vy, dvx, dvy = _box_gather(G, BI[q] - ox, BJ[q] - oy, q, UX, UY, K, OKX[q], OKY[q], WB)
            else:
                vx, vy, dvx, dvy = _gather_corners(G, q, K, B, ox, oy)
            dx[p, 0] = dt * vx
            dx[p, 1] = dt * vy
            nvx = pic * vx + flip * (v[p, 0] + dvx)   # FLIP with a PIC blend, as the point kernel
            nvy = pic * vy + flip * (v[p, 1] + dvy)
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
                if OK[q]:
                    _box_remap(G, BI[q] - ox, BJ[q] - oy, K, OKX[q], OKY[q], WB, mvx, mvy)
                else:
                    _scatter_corners(G, 5, q, K, B, ox, oy, mvx, mvy)
    return vmax2 ** 0.5, bad


def _g2p_kinematics_cpdi(x, m, vol, strain, de, dw, F, vol0, dq, vel_field, dx, dt,
                         gravity, load_id, load_w, load_vec,
                         G, ox, oy, origin, inv_h, ncx, ncy, shape):
    """CPDI ``g2p_kinematics``: L = sum_i v_i (x) grad w_i = sum_c v(x_c) (x) g_c, then as the
    point kernel. The block's corners come from F before this step's update (every transfer of
    the step uses them)."""
    work = 0.0
    tag = shape[0]
    K = stencil(tag)
    B = _cpdi_buffers(tag)
    GV, BI, BJ, UX, UY, OK, OKX, OKY = B[1], B[2], B[3], B[4], B[5], B[6], B[7], B[8]
    nwx, nwy = G.shape[0], G.shape[1]
    n = x.shape[0]
    for p0 in range(0, n, BLOCK):
        nq = min(BLOCK, n - p0)
        if de is not None:
            _cpdi_block(x, p0, nq, origin, inv_h, ncx, ncy, shape, ox, oy, nwx, nwy, B)
        for q in range(nq):
            p = p0 + q
            if de is not None:
                lxx = 0.0
                lxy = 0.0
                lyx = 0.0
                lyy = 0.0
                if OK[q]:
                    # L = sum_i v_i (x) [(n_1 - n_3) a/V + (n_2 - n_4) b/V]: the two sums first
                    xa, xb, ya, yb = _box_gradient(G, BI[q] - ox, BJ[q] - oy, q, UX, UY, K, OKX[q], OKY[q],
                                                   vel_field)
                    ax, ay, bx, by = GV[0, q], GV[1, q], GV[2, q], GV[3, q]
                    lxx = xa * ax + xb * bx
                    lxy = xa * ay + xb * by
                    lyx = ya * ax + yb * bx
                    lyy = ya * ay + yb * by
                else:
                    lxx, lxy, lyx, lyy = _gradient_corners(G, vel_field, q, K, B, ox, oy)
                strain_increment(p, dt * inv_h, lxx, lxy, lyx, lyy, de, dw, strain, vol, F, vol0, dq)
            if dx is not None:
                work += move(p, x, dx, m, gravity, load_id, load_w, load_vec)
    return work


# -- the kernels: the point/GIMP or the CPDI implementation, chosen by the type of ``shape`` --

def _p2g(x, m, v, vol, stress, gravity, load_id, load_w, load_vec,
         G, ox, oy, origin, inv_h, ncx, ncy, shape):
    raise NotImplementedError  # only called from jitted code (the overload below)


@overload(_p2g)
def _p2g_overload(x, m, v, vol, stress, gravity, load_id, load_w, load_vec,
                  G, ox, oy, origin, inv_h, ncx, ncy, shape):
    return _p2g_cpdi if is_cpdi(shape) else _p2g_point


def _g2p_velocity(x, m, v, pic, G, ox, oy, origin, inv_h, ncx, ncy, shape, remap, dx, dt):
    raise NotImplementedError


@overload(_g2p_velocity)
def _g2p_velocity_overload(x, m, v, pic, G, ox, oy, origin, inv_h, ncx, ncy, shape, remap, dx, dt):
    return _g2p_velocity_cpdi if is_cpdi(shape) else _g2p_velocity_point


def _g2p_kinematics(x, m, vol, strain, de, dw, F, vol0, dq, vel_field, dx, dt,
                    gravity, load_id, load_w, load_vec,
                    G, ox, oy, origin, inv_h, ncx, ncy, shape):
    raise NotImplementedError


@overload(_g2p_kinematics)
def _g2p_kinematics_overload(x, m, vol, strain, de, dw, F, vol0, dq, vel_field, dx, dt,
                             gravity, load_id, load_w, load_vec,
                             G, ox, oy, origin, inv_h, ncx, ncy, shape):
    return _g2p_kinematics_cpdi if is_cpdi(shape) else _g2p_kinematics_point


def p2g(x, m, v, vol, stress, gravity, load_id, load_w, load_vec,
        G, ox, oy, origin, inv_h, ncx, ncy, shape):
    return _p2g(x, m, v, vol, stress, gravity, load_id, load_w, load_vec,
                G, ox, oy, origin, inv_h, ncx, ncy, shape)


def g2p_velocity(x, m, v, pic, G, ox, oy, origin, inv_h, ncx, ncy, shape, remap, dx, dt):
    return _g2p_velocity(x, m, v, pic, G, ox, oy, origin, inv_h, ncx, ncy, shape, remap, dx, dt)


def g2p_kinematics(x, m, vol, strain, de, dw, F, vol0, dq, vel_field, dx, dt,
                   gravity, load_id, load_w, load_vec,
                   G, ox, oy, origin, inv_h, ncx, ncy, shape):
    return _g2p_kinematics(x, m, vol, strain, de, dw, F, vol0, dq, vel_field, dx, dt,
                           gravity, load_id, load_w, load_vec,
                           G, ox, oy, origin, inv_h, ncx, ncy, shape)


p2g.__doc__ = _p2g_point.__doc__
g2p_velocity.__doc__ = _g2p_velocity_point.__doc__
g2p_kinematics.__doc__ = _g2p_kinematics_point.__doc__
p2g = nb.njit(cache=True)(p2g)
g2p_velocity = nb.njit(cache=True)(g2p_velocity)
g2p_kinematics = nb.njit(cache=True)(g2p_kinematics)
