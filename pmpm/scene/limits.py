"""What a scene asks of the machine, refused before it is asked: memory and step count.

Memory (docs/scenes.md, "Limits"): before anything is allocated, the bytes one rank needs are
estimated from the grid window it will hold (its share of node columns plus ghosts, full extent
of the other axis, :data:`BYTES_PER_NODE` each) and the particles (every rank places the whole
scene's points, :data:`BYTES_PER_PLACED_POINT` each, and keeps the full state of its share,
:data:`BYTES_PER_PARTICLE` each plus the materials' state). A scene needing more than the memory
available to a rank (``MemAvailable`` of /proc/meminfo shared by the ranks of this node) is
refused naming ``grid.cells``. The estimate is computed in Python floats, so no size overflows.

Time step: the CFL step ``cfl h / c`` (the particle speed only makes it smaller) or the fixed
``time_step`` must be a positive finite number, and ``end_time / dt`` at most
``solver.max_estimated_steps``; a fixed ``time_step`` above the stable ``h / (c + |v|max)`` is
refused unless ``solver.allow_unstable_time_step = true``.
"""
import math
import os

from pmpm.errors import ConfigError

__all__ = ["estimate_particles", "estimate_bytes", "available_bytes", "check_memory",
           "check_time_step", "check_work_bounds", "check_override_depth", "BYTES_PER_NODE",
           "BYTES_PER_PARTICLE", "BYTES_PER_PLACED_POINT", "MAX_FRAMES", "MAX_HISTORY_ROWS",
           "MAX_CHECKPOINTS", "MAX_XPIC_ORDER", "THICKNESS_RANGE", "MAX_OVERRIDE_DEPTH"]

# -- bounds on the numbers that size a run's work (issue 35, deliverable 5) ---------------------

#: frames a run may write: each frame holds every particle's output fields (a 50,000-particle
#: scene's frame of x, v, stress, strain is 4 MB), so 1e5 frames is already 400 GB; a larger
#: count comes from a mistyped interval, not from a run anyone can store
MAX_FRAMES = 100_000
#: history rows (tracked points, energies, section cuts: a few hundred bytes a row with every
#: table): 1e7 rows is gigabytes and more rows than any run's steps at the default step bound
MAX_HISTORY_ROWS = 10_000_000
#: checkpoints: each rewrites the whole particle state (two files alternate, so the disk holds
#: two), and the writing time is a full frame's; 1e5 is already hours of writing at 0.1 s each
MAX_CHECKPOINTS = 100_000
#: XPIC(m) costs m - 1 grid-particle-grid passes and halo rounds per step (docs/effects.md): at
#: 16 the step already costs several times FLIP's; Hammerquist & Nairn (2017) use m <= 5 and
#: report the filtered modes converged by then, so a larger m buys nothing but time
MAX_XPIC_ORDER = 16
#: out-of-plane thickness (m): mass, volume and every force scale with it, and the energies with
#: its square through the velocities it sets; outside 1 nm to 1000 km they under- or overflow in
#: double precision (1e308 made the first step's energies infinite; 5e-324 made masses 0)
THICKNESS_RANGE = (1e-9, 1e6)
#: nesting of an override dict (a scene's dotted keys are a few levels deep); deeper nesting is
#: refused before any recursion (Python's limit is 1000 frames)
MAX_OVERRIDE_DEPTH = 64
#: smallest end time: its default output intervals (end_time / 20, / 1000) stay normal doubles
MIN_END_TIME = 1000 * 2.2250738585072014e-308


def _finite_positive(value):
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value > 0


def check_work_bounds(scene):
    """Refuse, naming the key, a number that sizes the run's work beyond what it can afford:
    end time (nan, inf, subnormal), output frames, history rows and checkpoints to the end
    time, XPIC's order, thicknesses. Applied to every scene, also a Scene built in Python and
    handed to :func:`pmpm.run` (its fields never passed the TOML parser)."""
    end = scene.solver.end_time
    if not _finite_positive(end) or end < MIN_END_TIME:
        raise ConfigError("solver.end_time", f"must be a finite number >= {MIN_END_TIME:.3g} s (got {end!r})")
    out = scene.output
    for key, interval, cap, what in (("output.interval", out.interval, MAX_FRAMES, "frames"),
                                     ("output.history_interval", out.history_interval, MAX_HISTORY_ROWS,
                                      "history rows"),
                                     ("output.checkpoint_interval", out.checkpoint_interval, MAX_CHECKPOINTS,
                                      "checkpoints")):
        if interval is None and key == "output.checkpoint_interval":
            continue
        if not _finite_positive(interval):
            raise ConfigError(key, f"must be a positive finite number (got {interval!r})")
        count = end / interval
        if not count <= cap:
            raise ConfigError(key, f"{interval:.3g} s gives {count:.3g} {what} to solver.end_time = {end:.3g} s, "
                                   f"more than {cap:,} (a run cannot store them)")
    order = getattr(scene.solver, "xpic_order", 2)
    if not isinstance(order, int) or isinstance(order, bool) or not 1 <= order <= MAX_XPIC_ORDER:
        raise ConfigError("solver.xpic_order", f"must be an integer from 1 to {MAX_XPIC_ORDER} "
                                               f"(each order is a grid pass per step; got {order!r})")
    lo, hi = THICKNESS_RANGE
    things = [("thickness", scene.thickness)] + [(f"bodies[{k}].thickness", b.thickness)
                                                 for k, b in enumerate(scene.bodies)]
    for key, value in things:
        if not _finite_positive(value) or not lo <= value <= hi:
            raise ConfigError(key, f"must be from {lo:g} to {hi:g} m (got {value!r})")


def check_override_depth(overrides, where, depth=0):
    """Refuse an overrides dict nested deeper than :data:`MAX_OVERRIDE_DEPTH` (iteratively, so
    5000 levels are one line, not a RecursionError)."""
    stack = [(overrides, 0)]
    while stack:
        node, level = stack.pop()
        if level > MAX_OVERRIDE_DEPTH:
            raise ConfigError(where, f"nested more than {MAX_OVERRIDE_DEPTH} tables deep")
        if isinstance(node, dict):
            stack.extend((v, level + 1) for v in node.values())
        elif isinstance(node, list):
            stack.extend((v, level + 1) for v in node)

#: window arrays per node: G (7 float64 fields), bc_mask (2 int8), bc_vel (2 float64), plus the
#: kernels' per-node scratch (a second copy of G in the halo exchange)
BYTES_PER_NODE = 2 * 7 * 8 + 2 + 2 * 8
#: fields a rank keeps per owned particle: the core fields (id, x, x0, v, m, vol, stress, mat,
#: body = 112 bytes) plus the step's scratch (dx, de, dw = 48 bytes), doubled for the copies of
#: migration, sorting and the last-good snapshot
BYTES_PER_PARTICLE = 2 * (112 + 48)
#: every rank places all points first (x, v, vol, m, mat, body = 56 bytes) and builds them from
#: lattices and masks of about the same size again
BYTES_PER_PLACED_POINT = 3 * 56


def estimate_particles(body, h):
    """Number of points a body's lattice will hold (an upper bound; 0 for meshes, known only
    once read)."""
    spacing = h / body.particles_per_cell
    geo = body.geometry
    if body.shape == "rectangle":
        return math.prod(max(1.0, round((u - l) / spacing)) for l, u in zip(geo["lower"], geo["upper"]))
    if body.shape == "circle":
        return math.pi * geo["radius"] ** 2 / spacing ** 2 + 4 * geo["radius"] / spacing + 1
    if body.shape == "polygon":
        xs, ys = zip(*geo["vertices"])
        return ((max(xs) - min(xs)) / spacing + 1) * ((max(ys) - min(ys)) / spacing + 1)
    if body.shape == "i_section":
        length = math.dist(geo["start"], geo["end"])
        return (length / spacing + 1) * (geo["depth"] / spacing + 1)
    return 0.0


def estimate_bytes(scene, n_ranks, state_floats=0):
    """(window bytes, particle bytes) one rank of ``n_ranks`` needs, as floats."""
    nodes = [float(c) + 1 for c in scene.grid.cells]
    ghost = 3  # the widest basis (cubic) needs the most ghost columns
    axis_nodes = max(nodes) / n_ranks + 2 * ghost
    window = min(nodes) * min(max(nodes), axis_nodes) * BYTES_PER_NODE
    n = sum(estimate_particles(b, scene.grid.cell_size) for b in scene.bodies)
    particles = n * BYTES_PER_PLACED_POINT + n / n_ranks * (BYTES_PER_PARTICLE + 8 * state_floats)
    return window, particles


def available_bytes():
    """Memory available on this machine now (``MemAvailable``), or None if unknown."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return float(os.sysconf("SC_AVPHYS_PAGES")) * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def _size(b):
    for unit in ("B", "KB", "MB", "GB", "TB", "PB"):
        if b < 1024 or unit == "PB":
            return f"{b:.3g} {unit}"
        b /= 1024
    return f"{b:.3g} PB"


def check_memory(scene, n_ranks=1, ranks_on_node=1, state_floats=0, available=None):
    """Refuse (ConfigError naming ``grid.cells``) a scene one rank cannot hold in memory.

    Parameters
    ----------
    scene : Scene
    n_ranks : int or float
        Ranks sharing the grid and particles (``math.inf``: what no rank count shrinks).
    ranks_on_node : int
        Ranks sharing this machine's memory.
    state_floats : int
        Floats of material state per particle.
    available : float, optional
        Bytes available on the machine (default: ``MemAvailable``).

    Returns
    -------
    float
        The estimate in bytes.
    """
    window, particles = estimate_bytes(scene, n_ranks, state_floats)
    need = window + particles
    avail = available_bytes() if available is None else available
    if avail is None or not math.isfinite(need):
        if math.isfinite(need):
            return need
        avail = 0.0
    share = avail / max(1, ranks_on_node)
    if need > share:
        raise ConfigError("grid.cells", f"a rank would need about {_size(need)} (grid window "
                                        f"{_size(window)}, particles {_size(particles)}) but has "
                                        f"about {_size(share)} available; use fewer cells or "
                                        f"particles, or more ranks (nodes)")
    return need


def check_time_step(scene, materials, vmax=0.0):
    """Refuse a time step that is not positive and finite, too many steps, or a fixed step
    above the stable one (unless allowed). ``materials`` are built material objects in the
    order of ``scene.materials``; ``vmax`` the largest initial particle speed (0 at parse time,
    where the checks are the bounds that the speed can only tighten)."""
    cfg, h = scene.solver, scene.grid.cell_size
    labels = list(scene.materials)
    speeds = [m.wave_speed() for m in materials]
    k = max(range(len(speeds)), key=lambda i: speeds[i] if math.isfinite(speeds[i]) else math.inf)
    c, key = speeds[k], f"materials.{labels[k]}"
    if not (math.isfinite(c) and c > 0):
        raise ConfigError(key, f"wave speed {c:g} m/s is not a positive finite number "
                               f"(E and density out of range?)")
    if not math.isfinite(vmax):
        raise ConfigError("bodies", "an initial velocity is not finite")
    stable = h / (c + vmax)
    dt = cfg.time_step if cfg.time_step is not None else cfg.cfl * stable
    if not (math.isfinite(dt) and dt > 0):
        raise ConfigError(key, f"wave speed {c:.3g} m/s and cell size {h:g} give the time step "
                               f"{dt:g} s, not a positive number")
    steps = cfg.end_time / dt
    if steps > cfg.max_estimated_steps:
        raise ConfigError(key, f"wave speed {c:.3g} m/s gives dt = {dt:.3g} s, about {steps:.3g} "
                               f"steps to end_time, more than solver.max_estimated_steps = "
                               f"{cfg.max_estimated_steps}")
    # (the implicit integrator is unconditionally stable: its step is the scene's to choose)
    if cfg.time_step is not None and cfg.time_step > stable and not cfg.allow_unstable_time_step \
            and cfg.integrator == "explicit":
        raise ConfigError("solver.time_step", f"{cfg.time_step:.3g} s is above the stable step "
                                              f"{stable:.3g} s (cell size {h:g} / (wave speed {c:.3g} m/s of "
                                              f"{key} + particle speed {vmax:.3g} m/s)); set "
                                              f"solver.allow_unstable_time_step = true to run it anyway")
    return dt
