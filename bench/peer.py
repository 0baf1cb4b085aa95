"""``pmpm bench peer``: pmpm's cubic MUSL elastic step side by side with JIT-compiled peers.

The peers are Taichi programs (``pip install taichi``; an optional dependency: the command says
how to install it when it is missing) on Taichi's CPU backend with one thread and float64. They
are written here, as references and not as pmpm code, on the same block with the same particle
count, cell size, time step, elastic material and clamped base, the way a Taichi user writes
them (one field per quantity, particle loops with atomic scatters):

``musl`` (:class:`TaichiPeer`), the same work as pmpm's step, cubic B-splines::

    clear grid -> P2G (mass, momentum, internal force) -> grid update (v, dv, fixed base)
    -> G2P (FLIP velocity, move dt sum N v, MUSL re-map of m v) -> re-mapped grid velocity
    -> strain increment from it, elastic plane-stress update, volume -> move

``mls_quadratic``, ``mls_cubic`` (:class:`TaichiMLSPeer`), MLS-MPM with APIC as Taichi's own
MPM examples do it: one P2G (mass and affine momentum with the stress) and one G2P (velocity,
affine matrix, stress, volume, move) per step, quadratic (the examples' choice) or cubic.

Everything runs in one process, pinned by the caller to one core (``taskset -c 0``),
interleaved (pmpm, peer 1, peer 2, ..., pmpm, ...), so a drift of a shared machine hits all
alike; each sample is the process CPU time of ``--steps`` steps, and the figures are medians.
A ratio is peer / pmpm time per particle-step: above 1 pmpm is faster. The command also prints
the host's CPU model and pmpm's memory-bandwidth floor: the bytes its step must stream per
particle (pmpm.benchmarks.throughput.step_bytes_per_particle) over this core's measured STREAM
triad bandwidth, and the step's cost against it.
"""
import json
import math
import statistics
import sys
import time

from pmpm.benchmarks.args import positive
from pmpm.benchmarks.block import block_scene

__all__ = ["peer", "PmpmSide", "TaichiPeer", "TaichiMLSPeer", "PEERS", "interleave", "INSTALL_HINT"]

INSTALL_HINT = ("pmpm bench peer needs the peer, Taichi (an optional dependency): "
                "python -m pip install taichi")

#: steps run before timing (first touch of the arrays, the peer's compilation)
WARM_STEPS = 10


class PmpmSide:
    """pmpm's step on the benchmark block (cubic or ``shape``, MUSL, elastic, one rank)."""

    name = "pmpm"

    def __init__(self, particles, shape="cubic", scheme="musl"):
        from mpi4py import MPI
        from pmpm.build import build_solver
        if shape != "cubic" or scheme != "musl":
            self.name = f"pmpm_{shape}" if scheme == "musl" else f"pmpm_{scheme}_{shape}"
        self.label = f"pmpm {scheme.upper()} ({shape})"
        self.scene = block_scene(particles, shape, scheme, "elastic")
        self.solver = build_solver(self.scene, MPI.COMM_SELF)
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


def _block_particles(geo):
    """Positions (n, 2) and initial velocities of the block's particles: the centres of a
    ppc x ppc sub-grid of each cell, in cell order, with pmpm's shear velocity field."""
    import numpy as np
    h, ppc = geo["h"], geo["ppc"]
    nbx = int(round((geo["x1"] - geo["x0"]) / h))
    nby = int(round(geo["height"] / h))
    sub = (np.arange(ppc) + 0.5) / ppc
    cx = (np.arange(nbx)[:, None] + sub[None, :]).ravel() * h + geo["x0"]
    cy = (np.arange(nby)[:, None] + sub[None, :]).ravel() * h
    X, Y = np.meshgrid(cx, cy, indexing="ij")
    pos = np.column_stack([X.ravel(), Y.ravel()])
    vel = np.column_stack([2.0 * pos[:, 1] / geo["height"], np.zeros(len(pos))])
    return pos, vel


_taichi_started = False


def _taichi(fresh=False):
    """Taichi on its CPU backend, one thread, float64. Taichi has one runtime per process:
    ``fresh`` starts a new one (freeing every field); the programs of one comparison share it."""
    global _taichi_started
    import taichi as ti
    if fresh or not _taichi_started:
        ti.reset()
        ti.init(arch=ti.cpu, cpu_max_num_threads=1, default_fp=ti.f64, default_ip=ti.i32,
                log_level=ti.WARN, offline_cache=True)
        _taichi_started = True
    return ti


class TaichiPeer:
    """The peer's MUSL step in Taichi (CPU, one thread, float64) on the block of
    ``block_scene(particles)``; see the module docstring."""

    name = "taichi"
    label = "Taichi MUSL (cubic)"

    def __init__(self, particles):
        import numpy as np
        ti = _taichi()
        geo = _block_geometry(block_scene(particles, "cubic", "musl", "elastic"))
        h, ppc = geo["h"], geo["ppc"]
        pos, vel = _block_particles(geo)
        n = len(pos)
        self.n = n
        vol0 = (h / ppc) ** 2
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


class TaichiMLSPeer:
    """An MLS-MPM step in Taichi the way Taichi's own MPM examples (mpm88, mpm99) write it:
    APIC transfers with the affine matrix C, one P2G and one G2P per step, B-spline weights of
    ``order`` 2 (quadratic, the examples' choice) or 3 (cubic). Same block, particle count,
    cell size, time step and clamped base as pmpm's; the stress is pmpm's: a plane-stress
    linear elastic increment from the strain rate sym(C) (hypoelastic, small strain), the
    volume from tr(C). Per step::

        clear grid (m, m v) -> P2G (m, m v + (m C - dt V D^-1 sigma)(x_i - x_p))
        -> grid update (v = m v / m, fixed base) -> G2P (v, C, sigma, V, x)

    with D^-1 = 4 / h^2 (quadratic) or 3 / h^2 (cubic), the MLS-MPM inertia tensor's inverse.
    """

    def __init__(self, particles, order=2):
        import numpy as np
        ti = _taichi()
        self.order = order
        self.name = f"taichi_mls_{'quadratic' if order == 2 else 'cubic'}"
        self.label = f"Taichi MLS-MPM APIC ({'quadratic' if order == 2 else 'cubic'})"
        geo = _block_geometry(block_scene(particles, "cubic", "musl", "elastic"))
        h, ppc = geo["h"], geo["ppc"]
        pos, vel = _block_particles(geo)
        n = self.n = len(pos)
        vol0 = (h / ppc) ** 2
        pad = 2  # every support whole on the padded grid (see TaichiPeer)
        gx, gy = geo["ncx"] + 1 + 2 * pad, geo["ncy"] + 1 + 2 * pad
        f64 = ti.f64
        self.x = ti.Vector.field(2, f64, n)
        self.v = ti.Vector.field(2, f64, n)
        self.C = ti.Matrix.field(2, 2, f64, n)
        self.stress = ti.Vector.field(3, f64, n)
        self.vol = ti.field(f64, n)
        self.m = ti.field(f64, n)
        self.gm = ti.field(f64, (gx, gy), offset=(-pad, -pad))
        self.gv = ti.Vector.field(2, f64, (gx, gy), offset=(-pad, -pad))
        self.x.from_numpy(pos)
        self.v.from_numpy(vel)
        self.vol.from_numpy(np.full(n, vol0))
        self.m.from_numpy(np.full(n, vol0 * geo["rho"]))
        self.stress.from_numpy(np.zeros((n, 3)))
        self.C.from_numpy(np.zeros((n, 2, 2)))
        self._kernels(ti, geo)

    def _kernels(self, ti, geo):
        x, v, C, stress, vol, m, gm, gv = self.x, self.v, self.C, self.stress, self.vol, self.m, self.gm, self.gv
        h = geo["h"]
        inv_h = 1.0 / h
        dt = geo["dt"]
        E, nu = geo["E"], geo["nu"]
        d11 = E / (1 - nu * nu)
        d12 = nu * d11
        d33 = 0.5 * (1 - nu) * d11
        cutoff = 1e-12 * geo["rho"] * h ** 2
        K = self.order + 1                       # nodes per axis
        Dinv = (4.0 if self.order == 2 else 3.0) * inv_h * inv_h

        @ti.func
        def stencil(s):
            # base node and weights of the quadratic (3 nodes) or cubic (4 nodes) B-spline
            base = ti.Vector([0, 0])
            fx = ti.Vector.zero(ti.f64, 2)
            w = ti.Matrix.zero(ti.f64, K, 2)
            if ti.static(self.order == 2):
                base = ti.cast(s - 0.5, ti.i32)
                fx = s - base
                for a in ti.static(range(2)):
                    w[0, a] = 0.5 * (1.5 - fx[a]) ** 2
                    w[1, a] = 0.75 - (fx[a] - 1.0) ** 2
                    w[2, a] = 0.5 * (fx[a] - 0.5) ** 2
            else:
                base = ti.cast(ti.floor(s), ti.i32) - 1
                fx = s - base
                for a in ti.static(range(2)):
                    for d in ti.static(range(4)):
                        r = ti.abs(fx[a] - d)
                        if r < 1.0:
                            w[d, a] = 0.5 * r * r * r - r * r + 2.0 / 3.0
                        elif r < 2.0:
                            t = 2.0 - r
                            w[d, a] = t * t * t / 6.0
            return base, fx, w

        @ti.kernel
        def clear():
            for I in ti.grouped(gm):
                gm[I] = 0.0
                gv[I] = ti.Vector.zero(ti.f64, 2)

        @ti.kernel
        def p2g():
            for p in x:
                base, fx, w = stencil(x[p] * inv_h)
                sig = stress[p]
                S = ti.Matrix([[sig[0], sig[2]], [sig[2], sig[1]]])
                affine = m[p] * C[p] - (dt * vol[p] * Dinv) * S
                mv = m[p] * v[p]
                for i, j in ti.static(ti.ndrange(K, K)):
                    offset = ti.Vector([i, j])
                    dpos = (offset - fx) * h
                    weight = w[i, 0] * w[j, 1]
                    gv[base + offset] += weight * (mv + affine @ dpos)
                    gm[base + offset] += weight * m[p]

        @ti.kernel
        def grid_update():
            for I in ti.grouped(gm):
                mi = gm[I]
                if mi > cutoff and I[1] != 0:  # the clamped base
                    gv[I] = gv[I] / mi
                else:
                    gv[I] = ti.Vector.zero(ti.f64, 2)

        @ti.kernel
        def g2p():
            for p in x:
                base, fx, w = stencil(x[p] * inv_h)
                new_v = ti.Vector.zero(ti.f64, 2)
                new_C = ti.Matrix.zero(ti.f64, 2, 2)
                for i, j in ti.static(ti.ndrange(K, K)):
                    offset = ti.Vector([i, j])
                    dpos = (offset - fx) * h
                    weight = w[i, 0] * w[j, 1]
                    g_v = gv[base + offset]
                    new_v += weight * g_v
                    new_C += (Dinv * weight) * g_v.outer_product(dpos)
                v[p] = new_v
                C[p] = new_C
                exx = dt * new_C[0, 0]
                eyy = dt * new_C[1, 1]
                gxy = dt * (new_C[0, 1] + new_C[1, 0])
                stress[p] += ti.Vector([d11 * exx + d12 * eyy, d12 * exx + d11 * eyy, d33 * gxy])
                vol[p] *= 1.0 + exx + eyy
                x[p] += dt * new_v

        self._sync = ti.sync
        self._phases = (clear, p2g, grid_update, g2p)

    def run(self, steps):
        for _ in range(steps):
            for k in self._phases:
                k()
        self._sync()

    def kinetic_energy(self):
        """Sum of 1/2 m v^2 (for the test that the peer's program is a working MPM step)."""
        v = self.v.to_numpy()
        return float(0.5 * (self.m.to_numpy() * (v * v).sum(axis=1)).sum())


#: the peers ``pmpm bench peer`` runs: name -> constructor(particles)
PEERS = {"musl": TaichiPeer,
         "mls_quadratic": lambda n: TaichiMLSPeer(n, order=2),
         "mls_cubic": lambda n: TaichiMLSPeer(n, order=3)}


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


def _floor_bytes(solver):
    from pmpm.benchmarks.throughput import step_bytes_per_particle
    return step_bytes_per_particle(solver)


def _floor(solver):
    """(bytes per particle-step, measured bandwidth in bytes/s, floor in ns per particle-step):
    the bytes pmpm's step must stream (pmpm.benchmarks.throughput.step_bytes_per_particle) over
    this core's STREAM-triad bandwidth."""
    from pmpm.benchmarks.throughput import step_bytes_per_particle, stream_triad_bandwidth
    nbytes = step_bytes_per_particle(solver)
    bandwidth = stream_triad_bandwidth()
    return nbytes, bandwidth, nbytes / bandwidth * 1e9


def add_arguments(p):
    """Options of ``pmpm bench peer``."""
    p.add_argument("--particles", type=positive, nargs="+", default=[200_000, 1_000_000],
                    help="particle counts of the block (default 200000 1000000)")
    p.add_argument("--steps", type=positive, default=10, help="steps per timed repeat (default 10)")
    p.add_argument("--repeat", type=positive, default=7,
                    help="timed repeats, pmpm and the peer interleaved (default 7)")
    p.add_argument("--peers", nargs="+", choices=["musl", "mls_quadratic", "mls_cubic"],
                    default=["musl", "mls_quadratic", "mls_cubic"],
                    help="the Taichi programs: plain MUSL (cubic) and MLS-MPM with APIC "
                         "(quadratic, cubic); default all three")


def peer(args):
    """``pmpm bench peer``: returns the exit code."""
    try:
        import taichi  # noqa: F401
    except ImportError:
        print(f"pmpm: error: {INSTALL_HINT}", file=sys.stderr)
        return 2
    from pmpm.benchmarks.cpuinfo import cpu_model
    names = getattr(args, "peers", None) or list(PEERS)
    print(f"pmpm bench peer: {cpu_model()}; peers {', '.join(names)}; CPU time, medians of "
          f"{args.repeat} rounds of {args.steps} steps, interleaved", flush=True)
    results = []
    for n in args.particles:
        _taichi(fresh=True)
        # pmpm with the quadratic MLS program's stencil too: the same node count per particle;
        # and pmpm's own MLS scheme (pmpm.core.mls) with the stencil of each Taichi MLS program
        extra = [PmpmSide(n, "quadratic")] if "mls_quadratic" in names else []
        mls = {k: PmpmSide(n, shape, "mls") for k, shape in (("mls_quadratic", "quadratic"), ("mls_cubic", "cubic"))
               if k in names}
        extra += list(mls.values())
        sides = [PmpmSide(n)] + extra + [PEERS[k](n) for k in names]
        for s in sides:  # compile (the peers), first touch of the arrays
            s.run(WARM_STEPS)
        samples = interleave(sides, args.steps, args.repeat)
        pm = statistics.median(samples["pmpm"])
        nbytes, bandwidth, floor = _floor(sides[0].solver)
        res = {"particles": {s.name: s.n for s in sides}, "steps": args.steps, "repeat": args.repeat,
               "pmpm_ns_per_particle_step": pm, "bytes_per_particle_step": nbytes,
               "stream_bandwidth_GB_s": bandwidth / 1e9, "floor_ns_per_particle_step": floor,
               "pmpm_over_floor": pm / floor, "peers": {}, "samples_ns": samples}
        print(f"{sides[0].n:>9d} particles: pmpm {pm:.1f} ns/particle-step; memory floor "
              f"{floor:.1f} ns ({nbytes:.0f} bytes per particle-step at {bandwidth / 1e9:.1f} GB/s "
              f"STREAM triad): pmpm's step is {pm / floor:.1f} x the floor", flush=True)
        res["pmpm_mls"] = {}
        for key, side in mls.items():   # the MLS scheme's step and its own floor (fewer passes)
            t = statistics.median(samples[side.name])
            side_bytes = _floor_bytes(side.solver)
            side_floor = side_bytes / bandwidth * 1e9
            res["pmpm_mls"][side.name] = {"label": side.label, "ns_per_particle_step": t,
                                          "bytes_per_particle_step": side_bytes,
                                          "floor_ns_per_particle_step": side_floor, "over_floor": t / side_floor}
            print(f"{'':>9s} {side.label:<34s} {t:8.1f} ns/particle-step; its floor {side_floor:.1f} ns "
                  f"({side_bytes:.0f} bytes): {t / side_floor:.1f} x the floor", flush=True)
        for s in sides[1 + len(extra):]:
            pe = statistics.median(samples[s.name])
            ratios = [b / a for a, b in zip(samples["pmpm"], samples[s.name])]
            res["peers"][s.name] = {"label": s.label, "particles": s.n, "ns_per_particle_step": pe,
                                    "ratio_peer_over_pmpm": pe / pm, "ratio_per_round": ratios}
            print(f"{'':>9s} {s.label:<34s} {pe:8.1f} ns/particle-step ({s.n} particles): "
                  f"peer/pmpm {pe / pm:.2f} (rounds {min(ratios):.2f}-{max(ratios):.2f})", flush=True)
            own = mls.get(s.name.replace("taichi_", ""))
            if own is not None:   # the Taichi MLS program against pmpm's MLS with the same stencil
                q = statistics.median(samples[own.name])
                rq = [b / a for a, b in zip(samples[own.name], samples[s.name])]
                res["peers"][s.name].update({f"{own.name}_ns_per_particle_step": q,
                                             f"ratio_peer_over_{own.name}": pe / q})
                print(f"{'':>9s} {'  against ' + own.label:<34s} {q:8.1f} ns/particle-step: "
                      f"peer/pmpm {pe / q:.2f} (rounds {min(rq):.2f}-{max(rq):.2f})", flush=True)
            if s.name == "taichi_mls_quadratic" and extra:
                q = statistics.median(samples[extra[0].name])
                rq = [b / a for a, b in zip(samples[extra[0].name], samples[s.name])]
                res["peers"][s.name].update(pmpm_quadratic_ns_per_particle_step=q,
                                            ratio_peer_over_pmpm_quadratic=pe / q)
                print(f"{'':>9s} {'  against pmpm MUSL (quadratic)':<34s} {q:8.1f} ns/particle-step: "
                      f"peer/pmpm {pe / q:.2f} (rounds {min(rq):.2f}-{max(rq):.2f})", flush=True)
        results.append(res)
        del sides
    import taichi as ti
    print(json.dumps({"cpu_model": cpu_model(),
                      "peer": f"taichi {'.'.join(map(str, ti.__version__))} cpu, 1 thread, f64",
                      "clock": "process CPU time", "results": results}))
    return 0
