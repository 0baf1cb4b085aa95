"""``pmpm bench peer``: pmpm's cubic MUSL elastic step side by side with a JIT-compiled peer.

The peer is Taichi (``pip install taichi``; an optional dependency: the command says how to
install it when it is missing) on its CPU backend with one thread and float64. Its program is
written here, as a reference and not as pmpm code: a plain MUSL step on the same block, with
the same particle count, cell size, time step, cubic B-splines and clamped base, the way a
Taichi user writes it (one field per quantity, particle loops with atomic scatters):

    clear grid -> P2G (mass, momentum, internal force) -> grid update (v, dv, fixed base)
    -> G2P (FLIP velocity, move dt sum N v, MUSL re-map of m v) -> re-mapped grid velocity
    -> strain increment from it, elastic plane-stress update, volume -> move

Both run in one process, pinned by the caller to one core (``taskset -c 0``), interleaved
(pmpm, peer, pmpm, peer, ...), so a drift of a shared machine hits both alike; each sample is
the process CPU time of ``--steps`` steps, and the figures are medians. The ratio is
peer / pmpm time per particle-step: above 1 pmpm is faster.
"""
import json
import math
import statistics
import sys
import time

from pmpm.benchmarks.block import block_scene

__all__ = ["peer", "PmpmSide", "TaichiPeer", "interleave", "INSTALL_HINT"]

INSTALL_HINT = ("pmpm bench peer needs the peer, Taichi (an optional dependency): "
                "python -m pip install taichi")

#: steps run before timing (first touch of the arrays, the peer's compilation)
WARM_STEPS = 10


class PmpmSide:
    """pmpm's step on the benchmark block (cubic, MUSL, elastic, one rank)."""

    name = "pmpm"

    def __init__(self, particles):
        from mpi4py import MPI
        from pmpm.core.solver import Solver
        self.scene = block_scene(particles, "cubic", "musl", "elastic")
        self.solver = Solver(self.scene, MPI.COMM_SELF)
        self.n = self.solver.particles.n

    def run(self, steps):
        for _ in range(steps):
            self.solver.step()


def _block_geometry(scene):
    """(cells x, cells y, h, particles per cell per axis, block x range, block height, E, nu,
    rho, dt) of the benchmark block, so the peer builds the same problem."""
    g, b = scene.grid, scene.bodies[0]
    mat = scene.materials[b.material]
    E, nu, rho = mat["E"], mat["nu"], mat["density"]
    c = math.sqrt(E / (rho * (1 - nu * nu)))
    lower, upper = b.geometry["lower"], b.geometry["upper"]
    return dict(ncx=g.cells[0], ncy=g.cells[1], h=g.cell_size, ppc=b.particles_per_cell,
                x0=lower[0], x1=upper[0], height=upper[1], E=E, nu=nu, rho=rho,
                dt=scene.solver.cfl * g.cell_size / c)


class TaichiPeer:
    """The peer's MUSL step in Taichi (CPU, one thread, float64) on the block of
    ``block_scene(particles)``; see the module docstring."""

    name = "taichi"

    def __init__(self, particles):
        import numpy as np
        import taichi as ti
        ti.reset()
        ti.init(arch=ti.cpu, cpu_max_num_threads=1, default_fp=ti.f64, default_ip=ti.i32,
                log_level=ti.WARN, offline_cache=True)
        geo = _block_geometry(block_scene(particles, "cubic", "musl", "elastic"))
        h, ppc = geo["h"], geo["ppc"]
        # particles at the centres of a ppc x ppc sub-grid of each cell of the block, in cell order
        nbx = int(round((geo["x1"] - geo["x0"]) / h))
        nby = int(round(geo["height"] / h))
        sub = (np.arange(ppc) + 0.5) / ppc
        cx = (np.arange(nbx)[:, None] + sub[None, :]).ravel() * h + geo["x0"]
        cy = (np.arange(nby)[:, None] + sub[None, :]).ravel() * h
        X, Y = np.meshgrid(cx, cy, indexing="ij")
        pos = np.column_stack([X.ravel(), Y.ravel()])
        n = len(pos)
        self.n = n
        vol0 = (h / ppc) ** 2
        vel = np.column_stack([2.0 * pos[:, 1] / geo["height"], np.zeros(n)])
        # the grid, padded by 2 nodes on every side so every cubic support is whole (the
        # block's base sits on the grid's edge; pmpm uses boundary-modified splines there)
        pad = 2
        gx, gy = geo["ncx"] + 1 + 2 * pad, geo["ncy"] + 1 + 2 * pad
        f64 = ti.f64
        self.x = ti.Vector.field(2, f64, n)
        self.v = ti.Vector.field(2, f64, n)
        self.dx = ti.Vector.field(2, f64, n)
        self.stress = ti.Vector.field(3, f64, n)
        self.vol = ti.field(f64, n)
        self.m = ti.field(f64, n)
        self.gm = ti.field(f64, (gx, gy), offset=(-pad, -pad))
        self.gmv = ti.Vector.field(2, f64, (gx, gy), offset=(-pad, -pad))
        self.gf = ti.Vector.field(2, f64, (gx, gy), offset=(-pad, -pad))
        self.gmv2 = ti.Vector.field(2, f64, (gx, gy), offset=(-pad, -pad))
        self.x.from_numpy(pos)
        self.v.from_numpy(vel)
        self.vol.from_numpy(np.full(n, vol0))
        self.m.from_numpy(np.full(n, vol0 * geo["rho"]))
        self.stress.from_numpy(np.zeros((n, 3)))
        self._kernels(ti, geo, pad)

    def _kernels(self, ti, geo, pad):
        x, v, dx, stress, vol, m = self.x, self.v, self.dx, self.stress, self.vol, self.m
        gm, gmv, gf, gmv2 = self.gm, self.gmv, self.gf, self.gmv2
        inv_h = 1.0 / geo["h"]
        dt = geo["dt"]
        E, nu = geo["E"], geo["nu"]
        d11 = E / (1 - nu * nu)
        d12 = nu * d11
        d33 = 0.5 * (1 - nu) * d11
        cutoff = 1e-12 * geo["rho"] * geo["h"] ** 2

        @ti.func
        def weights(fx):
            # cubic B-spline weights and derivatives (cell units) at distances fx - d,
            # fx = x / h - base in [1, 2)
            w = ti.Vector.zero(ti.f64, 4)
            dw = ti.Vector.zero(ti.f64, 4)
            for d in ti.static(range(4)):
                r = fx - d
                a = ti.abs(r)
                s = 1.0 if r >= 0 else -1.0
                if a < 1.0:
                    w[d] = 0.5 * a * a * a - a * a + 2.0 / 3.0
                    dw[d] = s * (1.5 * a * a - 2.0 * a)
                elif a < 2.0:
                    t = 2.0 - a
                    w[d] = t * t * t / 6.0
                    dw[d] = -s * 0.5 * t * t
            return w, dw

        @ti.kernel
        def clear():
            for I in ti.grouped(gm):
                gm[I] = 0.0
                gmv[I] = ti.Vector.zero(ti.f64, 2)
                gf[I] = ti.Vector.zero(ti.f64, 2)
                gmv2[I] = ti.Vector.zero(ti.f64, 2)

        @ti.kernel
        def p2g():
            for p in x:
                s = x[p] * inv_h
                base = ti.cast(ti.floor(s), ti.i32) - 1
                wx, dwx = weights(s[0] - base[0])
                wy, dwy = weights(s[1] - base[1])
                c = -vol[p] * inv_h
                sig = stress[p]
                mp = m[p]
                for i, j in ti.static(ti.ndrange(4, 4)):
                    w = wx[i] * wy[j]
                    gx = dwx[i] * wy[j]
                    gy = wx[i] * dwy[j]
                    I = base + ti.Vector([i, j])
                    gm[I] += w * mp
                    gmv[I] += w * mp * v[p]
                    gf[I] += c * ti.Vector([sig[0] * gx + sig[2] * gy, sig[2] * gx + sig[1] * gy])

        @ti.kernel
        def grid_update():
            for I in ti.grouped(gm):
                mi = gm[I]
                if mi > cutoff:
                    vi = gmv[I] / mi
                    dvi = gf[I] * (dt / mi)
                    if I[1] == 0:  # the clamped base
                        vi = ti.Vector.zero(ti.f64, 2)
                        dvi = ti.Vector.zero(ti.f64, 2)
                    gmv[I] = vi + dvi  # new velocity
                    gf[I] = dvi        # velocity change
                else:
                    gmv[I] = ti.Vector.zero(ti.f64, 2)
                    gf[I] = ti.Vector.zero(ti.f64, 2)

        @ti.kernel
        def g2p():
            for p in x:
                s = x[p] * inv_h
                base = ti.cast(ti.floor(s), ti.i32) - 1
                wx, _ = weights(s[0] - base[0])
                wy, _ = weights(s[1] - base[1])
                vn = ti.Vector.zero(ti.f64, 2)
                dv = ti.Vector.zero(ti.f64, 2)
                for i, j in ti.static(ti.ndrange(4, 4)):
                    w = wx[i] * wy[j]
                    I = base + ti.Vector([i, j])
                    vn += w * gmv[I]
                    dv += w * gf[I]
                vp = v[p] + dv
                v[p] = vp
                dx[p] = dt * vn
                mv = m[p] * vp
                for i, j in ti.static(ti.ndrange(4, 4)):
                    gmv2[base + ti.Vector([i, j])] += wx[i] * wy[j] * mv

        @ti.kernel
        def remapped_velocity():
            for I in ti.grouped(gm):
                mi = gm[I]
                if mi > cutoff and I[1] != 0:
                    gmv2[I] = gmv2[I] / mi
                else:
                    gmv2[I] = ti.Vector.zero(ti.f64, 2)

        @ti.kernel
        def strain_stress_move():
            for p in x:
                s = x[p] * inv_h
                base = ti.cast(ti.floor(s), ti.i32) - 1
                wx, dwx = weights(s[0] - base[0])
                wy, dwy = weights(s[1] - base[1])
                L = ti.Matrix.zero(ti.f64, 2, 2)
                for i, j in ti.static(ti.ndrange(4, 4)):
                    g = ti.Vector([dwx[i] * wy[j], wx[i] * dwy[j]])
                    L += gmv2[base + ti.Vector([i, j])].outer_product(g)
                c = dt * inv_h
                exx = c * L[0, 0]
                eyy = c * L[1, 1]
                gxy = c * (L[0, 1] + L[1, 0])
                stress[p] += ti.Vector([d11 * exx + d12 * eyy, d12 * exx + d11 * eyy, d33 * gxy])
                vol[p] *= 1.0 + exx + eyy
                x[p] += dx[p]

        self._sync = ti.sync
        self._phases = (clear, p2g, grid_update, g2p, remapped_velocity, strain_stress_move)

    def run(self, steps):
        for _ in range(steps):
            for k in self._phases:
                k()
        self._sync()

    def kinetic_energy(self):
        """Sum of 1/2 m v^2 (for the test that the peer's program is a working MPM step)."""
        v = self.v.to_numpy()
        return float(0.5 * (self.m.to_numpy() * (v * v).sum(axis=1)).sum())


def interleave(sides, steps, repeat, clock=time.process_time):
    """Run ``steps`` steps of every side in turn, ``repeat`` rounds; returns {name: [ns per
    particle-step of each round]}."""
    samples = {s.name: [] for s in sides}
    for _ in range(repeat):
        for s in sides:
            t0 = clock()
            s.run(steps)
            samples[s.name].append((clock() - t0) / (steps * s.n) * 1e9)
    return samples


def peer(args):
    """``pmpm bench peer``: returns the exit code."""
    try:
        import taichi  # noqa: F401
    except ImportError:
        print(f"pmpm: error: {INSTALL_HINT}", file=sys.stderr)
        return 2
    results = []
    for n in args.particles:
        sides = [PmpmSide(n), TaichiPeer(n)]
        for s in sides:  # compile (the peer), first touch of the arrays
            s.run(WARM_STEPS)
        samples = interleave(sides, args.steps, args.repeat)
        pm, pe = (statistics.median(samples[s.name]) for s in sides)
        ratios = [b / a for a, b in zip(samples["pmpm"], samples["taichi"])]
        res = {"particles": {"pmpm": sides[0].n, "taichi": sides[1].n}, "steps": args.steps,
               "repeat": args.repeat, "pmpm_ns_per_particle_step": pm, "peer_ns_per_particle_step": pe,
               "ratio_peer_over_pmpm": pe / pm, "ratio_per_round": ratios,
               "samples_ns": samples}
        print(f"{sides[0].n:>9d} particles (peer {sides[1].n}), {args.steps} steps x {args.repeat} rounds, "
              f"CPU time, median: pmpm {pm:.1f} ns/particle-step, taichi {pe:.1f} ns/particle-step, "
              f"ratio taichi/pmpm {pe / pm:.2f} (rounds {min(ratios):.2f}-{max(ratios):.2f})", flush=True)
        results.append(res)
        del sides
    import taichi as ti
    print(json.dumps({"peer": f"taichi {'.'.join(map(str, ti.__version__))} cpu, 1 thread, f64, cubic MUSL",
                      "clock": "process CPU time", "results": results}))
    return 0
