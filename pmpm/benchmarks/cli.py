"""``pmpm bench ...``: the benchmark sub-commands and their dispatch."""
from pmpm.benchmarks.block import MATERIALS

__all__ = ["add_bench_parser", "main"]


#: largest count a benchmark option takes (particles, steps, repeats): 10^9 particles already
#: need ~1 TB; a larger number is a typo (10^15) and would fail inside numpy, not here
MAX_COUNT = 10 ** 9


def _positive(text):
    """argparse type: an integer from 1 to MAX_COUNT (a bad value is a one-line error, exit 2)."""
    import argparse
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1 (got {value})")
    if value > MAX_COUNT:
        raise argparse.ArgumentTypeError(f"must be at most {MAX_COUNT:.0e} (got {value:.3g})")
    return value


def _finite_positive(text):
    """argparse type: a finite float > 0 and at most 1e15 (inf and nan refused)."""
    import argparse
    import math
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (math.isfinite(value) and 0 < value <= 1e15):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0 and at most 1e15 (got {text!r})")
    return value


def add_bench_parser(sub):
    """Register ``pmpm bench throughput|scaling`` on an argparse sub-parser set."""
    b = sub.add_parser("bench", help="benchmarks (throughput, scaling, ranks, peer, fixedcost, ...)")
    bs = b.add_subparsers(dest="bench", required=True)
    t = bs.add_parser("throughput", help="particle-steps per second on one core")
    t.add_argument("--particles", type=_positive, nargs="+", default=[200_000],
                   help="particle count(s) of the block, one measurement each (default 200000)")
    t.add_argument("--steps", type=_positive, default=20, help="steps per timed repeat (default 20)")
    t.add_argument("--repeat", type=_positive, default=5, help="number of timed repeats (default 5)")
    t.add_argument("--shape", default="cubic", choices=["linear", "quadratic", "cubic"],
                   help="B-spline shape functions (default cubic)")
    t.add_argument("--scheme", default="musl", choices=["usf", "usl", "musl"],
                   help="update scheme (default musl)")
    t.add_argument("--material", default="elastic", choices=sorted(MATERIALS),
                   help="material of the block (default elastic)")
    t.add_argument("--interpolation", default="point", choices=["point", "ugimp", "cpgimp", "cpdi"],
                   help="point B-splines, the B-spline GIMP (cubic only) or CPDI (any --shape)")
    t.add_argument("--track-F", dest="track_F", action="store_true",
                   help="keep the deformation gradient F although the material does not need it")
    t.add_argument("--phases", action="store_true",
                   help="also time every kernel call of the step (after the timed repeats)")
    e = bs.add_parser("effects", help="cost of each optional effect alone")
    e.add_argument("--particles", type=_positive, default=100_000, help="particles of the block (default 100000)")
    e.add_argument("--steps", type=_positive, default=10, help="steps per timed repeat (default 10)")
    e.add_argument("--repeat", type=_positive, default=5, help="number of timed repeats (default 5)")
    s = bs.add_parser("scaling", help="run under mpirun: compute/communication split per rank")
    s.add_argument("--mode", choices=["strong", "weak"], default="strong",
                   help="strong: fixed total size; weak: --particles per rank (default strong)")
    s.add_argument("--particles", type=_positive, default=1_000_000,
                   help="particles in total (strong) or per rank (weak) (default 1000000)")
    s.add_argument("--steps", type=_positive, default=20, help="steps per timed repeat (default 20)")
    s.add_argument("--repeat", type=_positive, default=3, help="number of timed repeats (default 3)")
    s.add_argument("--ppc", type=_positive, default=2,
                   help="particles per cell per direction (more particles on the same grid)")
    pe = bs.add_parser("peer", help="pmpm's cubic MUSL step side by side with JIT peers (Taichi MUSL and MLS-MPM)")
    pe.add_argument("--particles", type=_positive, nargs="+", default=[200_000, 1_000_000],
                    help="particle counts of the block (default 200000 1000000)")
    pe.add_argument("--steps", type=_positive, default=10, help="steps per timed repeat (default 10)")
    pe.add_argument("--repeat", type=_positive, default=7,
                    help="timed repeats, pmpm and the peer interleaved (default 7)")
    pe.add_argument("--peers", nargs="+", choices=["musl", "mls_quadratic", "mls_cubic"],
                    default=["musl", "mls_quadratic", "mls_cubic"],
                    help="the Taichi programs: plain MUSL (cubic) and MLS-MPM with APIC "
                         "(quadratic, cubic); default all three")
    fc = bs.add_parser("fixedcost", help="per-step fixed cost: small scenes against a large one")
    fc.add_argument("--particles", type=_positive, nargs="+", default=[2_000, 7_700, 8_000, 200_000],
                    help="particle counts of the blocks, timed round robin (default 2000 7700 8000 200000)")
    fc.add_argument("--repeat", type=_positive, default=7, help="timed rounds (default 7)")
    fc.add_argument("--work", type=_finite_positive, default=2e6, help="particle-steps per sample")
    fc.add_argument("--material", default="elastic", choices=sorted(MATERIALS),
                    help="the block's material (default elastic)")
    fc.add_argument("--frame", nargs="*", default=["elastic"], choices=["elastic", "elastoplastic"],
                    help="variants of the main job's scene (cases/portal_frame.toml, 0.05 m) to time "
                         "beside the blocks (default elastic; none: --frame with no value)")
    fc.add_argument("--output", action="store_true",
                    help="also time the --frame variants with their output, as `pmpm run` runs them")
    fc.add_argument("--output-steps", type=_positive, default=1500,
                    help="with --output: runs of this many steps and twice as many (default 1500)")
    fc.add_argument("--whole-window", action="store_true",
                    help="also time every case with the grid tiles off (each node pass over the whole window)")
    from pmpm.benchmarks import ranks
    ranks.add_arguments(bs.add_parser("ranks", help="the main job on 1 and 2 ranks, idle and under a background load"))
    from pmpm.benchmarks.accuracy import add_arguments
    add_arguments(bs.add_parser("accuracy", help="error against wall time over shape, ppc, cell size, scheme"))


def main(args):
    """Dispatch ``pmpm bench <name>``."""
    from pmpm.benchmarks.throughput import effects, throughput
    if args.bench == "throughput":
        return throughput(args)
    if args.bench == "accuracy":
        from pmpm.benchmarks.accuracy import accuracy
        return accuracy(args)
    if args.bench == "fixedcost":
        from pmpm.benchmarks.fixed_cost import fixed_cost
        return fixed_cost(args)
    if args.bench == "peer":
        from pmpm.benchmarks.peer import peer
        return peer(args)
    if args.bench == "ranks":
        from pmpm.benchmarks.ranks import ranks
        return ranks(args)
    if args.bench == "effects":
        return effects(args)
    from pmpm.benchmarks.scaling import scaling
    return scaling(args)
