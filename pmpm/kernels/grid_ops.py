"""Grid-node operations: explicit momentum update with essential BCs (paper eq. 4, step 8)."""
import numba as nb

__all__ = ["grid_update", "momentum_to_velocity"]


@nb.njit(cache=True)
def grid_update(G, dt, mass_cutoff, bc_mask, bc_vel, i_lo, i_hi, j_lo, j_hi):
    """(mv) += f dt, then v = (mv)/m with the BCs imposed, over window rows [i_lo, i_hi) x
    [j_lo, j_hi). Afterwards fields 1, 2 hold the new velocity and 3, 4 the velocity change
    (what FLIP adds to the particles). Nodes lighter than ``mass_cutoff`` get no velocity."""
    for i in range(i_lo, i_hi):
        for j in range(j_lo, j_hi):
            mi = G[i, j, 0]
            if mi <= mass_cutoff:
                for k in range(1, 5):
                    G[i, j, k] = 0.0
                continue
            inv_m = 1.0 / mi
            for d in range(2):
                v_old = G[i, j, 1 + d] * inv_m
                v_new = v_old + G[i, j, 3 + d] * dt * inv_m
                if bc_mask[i, j, d]:
                    v_new = bc_vel[i, j, d]
                G[i, j, 1 + d] = v_new
                G[i, j, 3 + d] = v_new - v_old


@nb.njit(cache=True)
def momentum_to_velocity(G, src, dst, mass_cutoff, bc_mask, bc_vel, i_lo, i_hi, j_lo, j_hi):
    """v = (mv)/m from momentum fields ``src`` into fields ``dst`` (may be the same), with the
    BCs imposed (MUSL re-map; USF start-of-step velocity)."""
    for i in range(i_lo, i_hi):
        for j in range(j_lo, j_hi):
            mi = G[i, j, 0]
            for d in range(2):
                if mi <= mass_cutoff:
                    G[i, j, dst + d] = 0.0
                elif bc_mask[i, j, d]:
                    G[i, j, dst + d] = bc_vel[i, j, d]
                else:
                    G[i, j, dst + d] = G[i, j, src + d] / mi


@nb.njit(cache=True)
def stress_power(stress, de, vol):
    """sum_p V_p sigma_p : de_p, the internal work of one half of a trapezoid step (called with
    the stress before and after the update, each weighted 1/2 by the caller)."""
    w = 0.0
    for p in range(stress.shape[0]):
        w += vol[p] * (stress[p, 0] * de[p, 0] + stress[p, 1] * de[p, 1] + stress[p, 2] * de[p, 2])
    return w
