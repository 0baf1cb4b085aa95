"""Command line: ``pmpm case.toml`` runs a scene; ``pmpm plot|export|bench ...`` the tools.

Bad input is one line naming the key or file and the reason, exit code 2, nothing written.
A run that goes unstable or loses particles stops on every rank with a message, saves its last
good state and exits with 3. Any other exception on any rank aborts every rank (no hang).
"""
import argparse
import logging
import sys

__all__ = ["main"]
logger = logging.getLogger("pmpm.cli")

EXIT_BAD_INPUT = 2
EXIT_RUN_FAILED = 3
_FILE_SUFFIXES = (".toml", ".msh", ".vtk", ".vtu", ".inp", ".h5", ".at2", ".csv", ".txt")


def _run_parser():
    p = argparse.ArgumentParser(prog="pmpm", description="Explicit MPM for elastoplastic structures "
                                "(also: pmpm plot OUT.h5, pmpm export OUT.h5, pmpm bench ...)")
    p.add_argument("case", help="scene file (TOML), see docs/scenes.md")
    p.add_argument("--restart", metavar="OUT.h5", help="continue from the newest checkpoint of this output")
    p.add_argument("--variant", help="run only this [variants.<name>] of the scene")
    p.add_argument("--check", action="store_true", help="validate the scene and exit")
    p.add_argument("--no-plots", action="store_true", help="skip CSV and PNG post-processing")
    p.add_argument("-q", "--quiet", action="store_true", help="warnings and errors only")
    return p


def _tool_parser():
    p = argparse.ArgumentParser(prog="pmpm")
    sub = p.add_subparsers(dest="tool", required=True)
    plot = sub.add_parser("plot", help="draw time histories and energies to PNG")
    plot.add_argument("files", nargs="+", help="output HDF5 file(s); several are overlaid")
    plot.add_argument("-o", "--outdir", default=None)
    export = sub.add_parser("export", help="convert frames for other tools (meshio)")
    export.add_argument("file")
    export.add_argument("--format", default="vtu", choices=["vtu", "xdmf"])
    export.add_argument("-o", "--outdir", default=None)
    from pmpm.benchmarks.cli import add_bench_parser
    add_bench_parser(sub)
    return p


def _fail(message, code):
    print(f"pmpm: error: {message}", file=sys.stderr)
    return code


def _bad_input(exc, case, rank):
    """One line on rank 0: ``case.toml: key: reason`` (or ``file: reason`` for a file key)."""
    import os
    if rank != 0:
        return EXIT_BAD_INPUT
    names_file = (exc.key == case or os.sep in exc.key or os.path.isfile(exc.key)
                  or exc.key.lower().endswith(_FILE_SUFFIXES))
    return _fail(str(exc) if names_file else f"{case}: {exc}", EXIT_BAD_INPUT)


def _tool(argv):
    import os
    args = _tool_parser().parse_args(argv)
    if args.tool == "bench":
        from pmpm.benchmarks.cli import main as bench_main
        return bench_main(args)
    from pmpm.log import setup_logging
    setup_logging(0)
    files = args.files if args.tool == "plot" else [args.file]
    for f in files:
        if not os.path.isfile(f):
            return _fail(f"{f}: no such file", EXIT_BAD_INPUT)
    outdir = args.outdir or os.path.dirname(os.path.abspath(files[0]))
    if args.tool == "plot":
        from pmpm.io import plot_results
        from pmpm.results.post import structural_outputs
        made = plot_results(files, outdir)
        for f in files:
            made += structural_outputs(f, outdir)
        for path in made:
            print(f"wrote {path}")
    elif args.format == "vtu":
        from pmpm.io import export
        for path in export(args.file, "vtu", outdir):
            print(f"wrote {path}")
    else:
        from pmpm.io import write_xdmf
        print(f"wrote {write_xdmf(args.file)}")
    return 0


def _scenes(args):
    from pmpm.scene.config import load_scene
    return load_scene(args.case, args.variant)


def run_case(argv):
    """``pmpm case.toml``: validate, run every variant, post-process. Returns the exit code."""
    args = _run_parser().parse_args(argv)
    from mpi4py import MPI
    from decomposition import install_abort_hook
    from pmpm.errors import ConfigError, ParticleExitError, UnstableRunError
    from pmpm.log import setup_logging
    comm = MPI.COMM_WORLD
    rank = comm.Get_rank()
    setup_logging(rank, args.quiet)
    try:
        scenes = _scenes(args)
    except ConfigError as exc:
        return _bad_input(exc, args.case, rank)
    if args.check:
        if rank == 0:
            print(f"{args.case}: valid ({len(scenes)} run(s))")
        return 0
    if args.restart and len(scenes) > 1:
        return _fail(f"{args.case}: --restart needs --variant (the scene has {len(scenes)} variants)",
                     EXIT_BAD_INPUT) if rank == 0 else EXIT_BAD_INPUT
    install_abort_hook(comm)
    from pmpm.run import Run
    paths = []
    for scene in scenes:
        try:
            run = Run(scene, comm, restart=args.restart)
        except ConfigError as exc:
            return _bad_input(exc, args.case, rank)
        except (FileNotFoundError, ValueError, OSError) as exc:
            if args.restart:
                return _fail(f"{args.restart}: cannot restart ({exc})", EXIT_BAD_INPUT) if rank == 0 else EXIT_BAD_INPUT
            raise
        try:
            summary = run.execute()
        except (UnstableRunError, ParticleExitError) as exc:
            return _fail(f"{args.case}: {exc}", EXIT_RUN_FAILED) if rank == 0 else EXIT_RUN_FAILED
        paths.append(summary["output"])
        if rank == 0:
            logger.info("done: %d steps in %.1f s wall -> %s", summary["steps"], summary["wall"], summary["output"])
    if rank == 0 and not args.no_plots:
        from pmpm.io.post import postprocess
        postprocess(scenes, paths)
    return 0


def main(argv=None):
    """Entry point of the `pmpm` console script; returns (and exits with) the exit code."""
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] in ("plot", "export", "bench"):
        return _tool(argv)
    return run_case(argv)


def console():
    sys.exit(main())


if __name__ == "__main__":
    sys.exit(main())
