"""``pmpm bench ...``: the benchmark sub-commands and their dispatch.

``throughput``, ``effects``, ``scaling``, ``fixedcost``, ``profile``, ``ranks`` and ``implicit`` are the package's own.
``accuracy`` and ``peer`` run drivers that live in the repository, not in the installed package
(``studies/accuracy.py``: sweeps against closed forms and an FE model; ``bench/peer.py``: Taichi
peers): from a checkout, with the checkout importable (its root the working directory of
``python -m pmpm`` or on ``PYTHONPATH``).
"""
import argparse
import importlib

from pmpm.benchmarks.args import MATERIALS, profile_arguments, ranks_arguments
from pmpm.benchmarks.args import finite_positive as _finite_positive
from pmpm.benchmarks.args import positive as _positive

__all__ = ["add_bench_parser", "main"]


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
    t.add_argument("--scheme", default="musl", choices=["usf", "usl", "musl", "mls"],
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
    profile_arguments(bs.add_parser("profile", help="a scene's step phase by phase with its output, "
                                    "against the 200k block (default cases/frame_3storey.toml)"))
    ranks_arguments(bs.add_parser("ranks", help="the main job on 1 and 2 ranks, idle and under a background load"))
    # the implicit integrator's portal (docs/implicit.md): its own options, parsed by its main
    p = bs.add_parser("implicit", help="the implicit against the explicit integrator: the portal frame, or with "
                      "--scenes portal frame3-step frame3-record their time to solution",
                      add_help=False)
    p.add_argument("driver_args", nargs=argparse.REMAINDER,
                   help="its options (pmpm bench implicit --help lists them: --cell, --dt, --static, ...; "
                        "with --scenes: pmpm bench implicit --scenes portal --help)")
    for name, (_module, _entry, text) in REPOSITORY_DRIVERS.items():
        p = bs.add_parser(name, help=f"{text} (from a checkout: module doc)", add_help=False)
        p.add_argument("driver_args", nargs=argparse.REMAINDER,
                       help=f"the driver's own options (pmpm bench {name} --help lists them)")


#: subcommands run by the repository's drivers: name -> (module, entry function, help)
REPOSITORY_DRIVERS = {
    "peer": ("bench.peer", "peer", "pmpm's cubic MUSL step side by side with JIT peers (Taichi MUSL and MLS-MPM)"),
    "accuracy": ("studies.accuracy", "accuracy", "error against wall time over shape, ppc, cell size, scheme"),
}


def _repository_driver(name, argv):
    """Run the repository driver of ``pmpm bench <name>`` with its own options ``argv``."""
    module_name, entry, _ = REPOSITORY_DRIVERS[name]
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError:
        print(f"pmpm: error: bench {name}: runs {module_name.replace('.', '/')}.py of a checkout of the "
              f"repository (not installed); run it from the checkout's root")
        return 2
    parser = argparse.ArgumentParser(prog=f"pmpm bench {name}")
    module.add_arguments(parser)
    return getattr(module, entry)(parser.parse_args(argv))


def main(args):
    """Dispatch ``pmpm bench <name>`` (the drivers imported here: ``pmpm --help`` needs only
    the options, no kernel module)."""
    from pmpm.benchmarks import case_profile, ranks
    from pmpm.benchmarks.fixed_cost import fixed_cost
    from pmpm.benchmarks.scaling import scaling
    from pmpm.benchmarks.throughput import effects, throughput
    from pmpm.benchmarks.implicit_tts import main as implicit_portal
    if args.bench == "implicit":
        return implicit_portal(args.driver_args)
    if args.bench in REPOSITORY_DRIVERS:
        return _repository_driver(args.bench, args.driver_args)
    if args.bench == "throughput":
        return throughput(args)
    if args.bench == "fixedcost":
        return fixed_cost(args)
    if args.bench == "ranks":
        return ranks.ranks(args)
    if args.bench == "profile":
        return case_profile.profile(args)
    if args.bench == "effects":
        return effects(args)
    return scaling(args)
