"""Command line: ``pmpm case.toml`` runs a scene; ``pmpm run|plot|export|bench|expand ...`` the tools
(``pmpm expand case.toml -o out.toml`` writes a scene's ``[frame]`` as the ordinary scene it stands for).

``pmpm --help`` lists the subcommands, ``pmpm <subcommand> --help`` their options.
``pmpm case.toml`` is short for ``pmpm run case.toml``: any first argument that is not a
subcommand's name is a scene file (a file named like a subcommand runs as ``pmpm ./plot``).

Bad input, a bad argument of any subcommand included, is one line naming the key, argument or
file and the reason (``pmpm: error: ...``), exit code 2, nothing written. A run that goes
unstable or loses particles stops on every rank with a message, saves its last good state
(``<stem>.lastgood.h5``) and exits with 3; a file that cannot be written (full disk) stops
every rank with one line naming it and exit code 4. Any other exception on any rank aborts every rank (no hang).
"""
import argparse
import logging
import os
import sys

from pmpm import __version__

__all__ = ["main", "build_parser", "SUBCOMMANDS"]
logger = logging.getLogger("pmpm.cli")

EXIT_BAD_INPUT = 2
EXIT_RUN_FAILED = 3
EXIT_WRITE_FAILED = 4   # an output or checkpoint file could not be written (full disk, I/O)
_FILE_SUFFIXES = (".toml", ".msh", ".vtk", ".vtu", ".inp", ".h5", ".at2", ".csv", ".txt")
SUBCOMMANDS = ("run", "plot", "export", "bench", "expand")


def _rank_env():
    """This process's MPI rank from the launcher's environment (argparse runs before MPI)."""
    for var in ("OMPI_COMM_WORLD_RANK", "PMI_RANK", "PMIX_RANK"):
        if var in os.environ:
            return int(os.environ[var])
    return 0


class _Parser(argparse.ArgumentParser):
    """argparse with pmpm's error convention: one line on stderr (rank 0 only), exit 2."""

    def error(self, message):
        from pmpm.errors import one_line
        where = self.prog.split(" ", 1)[1] + ": " if " " in self.prog else ""
        self.exit(EXIT_BAD_INPUT, f"pmpm: error: {one_line(where + message)}\n" if _rank_env() == 0 else None)


def _add_run(sub):
    p = sub.add_parser("run", help="run a scene (the default: pmpm case.toml = pmpm run case.toml)",
                       description="Run every variant of a scene (or one), write the HDF5 results, the "
                       "XDMF sidecar, CSV histories and plots into the scene's output directory.")
    p.add_argument("case", help="scene file (TOML), see docs/scenes.md")
    p.add_argument("--restart", metavar="OUT.h5", help="continue from the newest checkpoint of this output")
    p.add_argument("--variant", help="run only this [variants.<name>] of the scene")
    p.add_argument("--check", action="store_true", help="validate the scene and exit")
    p.add_argument("--no-plots", action="store_true", help="skip CSV and PNG post-processing")
    p.add_argument("-q", "--quiet", action="store_true", help="warnings and errors only")
    return p


def _add_expand(sub):
    p = sub.add_parser("expand", help="write a scene's [frame] table out as ordinary bodies, boundaries, ...",
                       description="Expand the [frame] table of a scene (nodes, members, sections, "
                       "supports) into the ordinary scene pmpm runs: [[bodies]], [[boundary]], "
                       "[[loads.forces]], [[output.section]], [[output.track]] (docs/scenes.md, Frames). "
                       "The scene is validated first; nothing is written if it is bad.")
    p.add_argument("case", help="scene file (TOML) with a [frame] table")
    p.add_argument("-o", "--output", metavar="EXPANDED.toml", help="file to write (default: standard output)")
    p.add_argument("--variant", help="apply this [variants.<name>] first (and write no variants)")
    return p


def build_parser():
    """Return the ``pmpm`` argument parser (subcommands run, plot, export, bench)."""
    p = _Parser(prog="pmpm", description="Explicit MPM for elastoplastic structures. "
                "`pmpm case.toml` runs a scene (short for `pmpm run case.toml`).",
                epilog="Docs: README.md, docs/scenes.md (scene files), docs/output.md (results), "
                "docs/api.md (Python API).")
    p.add_argument("--version", action="version", version=f"pmpm {__version__}",
                   help="print the version and exit")
    sub = p.add_subparsers(dest="command", metavar="{run,plot,export,bench,expand}", title="subcommands")
    _add_run(sub)
    _add_expand(sub)
    plot = sub.add_parser("plot", help="draw time histories and energies to PNG",
                          description="Plot the track histories and energies of results files; "
                          "several files (e.g. the variants of one scene) are overlaid.")
    plot.add_argument("files", nargs="+", metavar="OUT.h5", help="results file(s) written by a run")
    plot.add_argument("-o", "--outdir", default=None,
                      help="folder for the PNG files (default: the first file's folder)")
    export = sub.add_parser("export", help="convert results for ParaView/meshio (VTU series, XDMF)",
                            description="Export a results file: a VTU series with a .pvd (default) "
                            "or the XDMF sidecar of the HDF5 file (see docs/output.md).")
    export.add_argument("file", metavar="OUT.h5", help="results file written by a run")
    export.add_argument("--format", default="vtu", choices=["vtu", "xdmf"],
                        help="vtu: one .vtu per frame and a .pvd (default); xdmf: the sidecar")
    export.add_argument("-o", "--outdir", default=None,
                        help="output folder (default: <stem>_vtu/ beside the file for vtu, the "
                        "file's folder for xdmf)")
    from pmpm.benchmarks.cli import add_bench_parser
    add_bench_parser(sub)
    return p


def _fail(message, code):
    """Print the one error line (control characters escaped: one printable line)."""
    from pmpm.errors import one_line
    print(f"pmpm: error: {one_line(message)}", file=sys.stderr)
    return code


def _bad_input(exc, case, rank):
    """One line on rank 0: ``case.toml: key: reason`` (or ``file: reason`` for a file key)."""
    import os
    if rank != 0:
        return EXIT_BAD_INPUT
    key = str(exc.key)
    try:
        is_file = os.path.isfile(key)
    except (ValueError, OSError):  # a NUL in the name
        is_file = False
    names_file = key == case or os.sep in key or is_file or key.lower().endswith(_FILE_SUFFIXES)
    return _fail(str(exc) if names_file else f"{case}: {exc}", EXIT_BAD_INPUT)


def _check_results(files):
    """Return the one-line error of the first file that is not a pmpm results file, or None."""
    from pmpm.io.hdf5 import check_results_file
    for f in files:
        try:
            check_results_file(f)
        except ValueError as exc:
            return f"{f}: {exc}"
    return None


def _tool(args):
    """``pmpm plot|export|bench``: returns the exit code."""
    if args.command == "bench":
        from pmpm.benchmarks.cli import main as bench_main
        return bench_main(args)
    from pmpm.errors import ConfigError
    from pmpm.log import setup_logging
    setup_logging(0, quiet=True)  # the tool prints what it wrote itself, one line a file
    files = args.files if args.command == "plot" else [args.file]
    problem = _check_results(files)
    if problem:
        return _fail(problem, EXIT_BAD_INPUT)
    if args.outdir and os.path.exists(args.outdir) and not os.path.isdir(args.outdir):
        return _fail(f"{args.outdir}: --outdir is not a folder", EXIT_BAD_INPUT)
    try:
        if args.command == "plot":
            from pmpm.io import ownership, plot_results
            from pmpm.io.plot import scene_stem
            from pmpm.results.post import structural_outputs  # sections and reactions, if any
            outdir = args.outdir or os.path.dirname(os.path.abspath(files[0]))
            with ownership.writing(scene_stem(files[0])):  # all the command's files, or none
                written = plot_results(files, outdir)
                for f in files:
                    written += structural_outputs(f, outdir)
        else:
            from pmpm.io import export
            written = export(args.file, args.format, args.outdir)
    except ConfigError as exc:  # a foreign file where the tool would write (pmpm.io.ownership)
        return _fail(str(exc), EXIT_BAD_INPUT)
    except OSError as exc:  # an unwritable folder, a read-only results file (xdmf adds /views)
        return _fail(f"{exc.filename or files[0]}: {exc.strerror or exc}", EXIT_BAD_INPUT)
    except (ValueError, KeyError) as exc:  # a results file without what the tool needs (positions)
        text = str(exc).strip("'\"")
        return _fail(text if text.startswith(files[0]) else f"{files[0]}: {text}", EXIT_BAD_INPUT)
    for path in written:
        print(f"wrote {path}")
    return 0


def _scenes(args):
    from pmpm.scene.config import load_scene
    # PETSc options on the command line (implicit integrator) become [solver.petsc] keys
    petsc = {f"solver.petsc.{name}": value for name, value in getattr(args, "petsc", {}).items()}
    return load_scene(args.case, args.variant, petsc or None)


def _frame_report(args):
    """What the scene's [frame] generates (after the variant, when one is chosen)."""
    from pmpm.scene.config import apply_overrides, read_toml
    from pmpm.scene.frame import frame_report
    data = read_toml(args.case)
    if args.variant:
        data = apply_overrides(data, data["variants"][args.variant], f"variants.{args.variant}")
    return frame_report(data)


def expand_case(args):
    """``pmpm expand case.toml [-o out.toml]``: the scene with its frame expanded, as TOML."""
    from pmpm.errors import ConfigError
    from pmpm.scene.config import apply_overrides, load_scene, read_toml
    from pmpm.scene.frame import expand_frame
    from pmpm.scene.toml_writer import dumps
    try:
        load_scene(args.case, args.variant)  # every variant valid (or the one), as a run checks
        data = read_toml(args.case)
        if args.variant:
            data = apply_overrides(data, data["variants"][args.variant], f"variants.{args.variant}")
            data.pop("variants")
        masses = bool(data.get("frame", {}).get("masses"))
        for name, overrides in data.get("variants", {}).items():
            if any(k == "frame" or k.startswith("frame.") for k in overrides):
                raise ConfigError(f"variants.{name}", "changes the [frame] table: expand it with "
                                                      "--variant (an expanded file has no frame to change)")
            if masses and any(k == "materials" or k.startswith("materials.") for k in overrides):
                raise ConfigError(f"variants.{name}", "changes a material that the frame's nodal masses copy: "
                                                      "expand it with --variant")
        if "frame" not in data:
            raise ConfigError(args.case, "has no [frame] table to expand")
        text = dumps(expand_frame(data), header=f"expanded by pmpm {__version__} from {os.path.basename(args.case)}"
                     + (f", variant {args.variant}" if args.variant else "")
                     + ": the bodies, boundaries, loads, section cuts\nand tracked points first in each "
                       "list were generated from its [frame] table (docs/scenes.md, Frames)")
    except ConfigError as exc:
        return _bad_input(exc, args.case, 0)
    if args.output is None:
        sys.stdout.write(text)
        return 0
    from pmpm.io import ownership
    # through the gate: never the scene under any name (same device and inode: a link, a hard
    # link, a path through a linked folder), never a link or a FIFO; written to an exclusive
    # temporary and renamed, so a full disk leaves the old file whole
    ownership.protect_input(args.case)
    try:
        ownership.replace_into(args.output, lambda fh: fh.write(text))
    except ownership.ForeignFileError as exc:
        return _fail(str(exc), EXIT_BAD_INPUT)
    except OSError as exc:
        return _fail(f"{args.output}: cannot write ({exc.strerror or type(exc).__name__})", EXIT_WRITE_FAILED)
    print(f"wrote {args.output}")
    return 0


def run_case(args):
    """``pmpm case.toml``: validate, run every variant, post-process. Returns the exit code."""
    from mpi4py import MPI
    from decomposition import install_abort_hook
    from pmpm.errors import ConfigError, OutputWriteError, ParticleExitError, UnstableRunError
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
            for line in _frame_report(args):
                print(line)
            from pmpm.scene.setup_particles import load_box_report
            for scene in scenes:  # a load box that catches several bodies is said, not refused
                for line in load_box_report(scene):
                    print(line)
            # each run built as it would start (on this rank alone): its size and time step,
            # the memory and time-step checks, and the effects it switches on
            from pmpm.build import build_solver
            from pmpm.runner import describe_effects
            from pmpm.scene.names import run_name
            for scene in scenes:
                try:
                    solver = build_solver(scene, MPI.COMM_SELF)
                except ConfigError as exc:
                    return _bad_input(exc, args.case, rank)
                print(f"{run_name(scene)}: {solver.n_total} particles, grid {solver.grid.cells[0]} x "
                      f"{solver.grid.cells[1]} cells of {solver.grid.h:g}, {scene.solver.integrator} "
                      f"integrator, dt {solver.dt:.3g} s, end {scene.solver.end_time:g} s")
                for line in describe_effects(scene, solver):
                    print(f"  effect on: {line}")
        return 0
    if args.restart and len(scenes) > 1:
        return _fail(f"{args.case}: --restart needs --variant (the scene has {len(scenes)} variants)",
                     EXIT_BAD_INPUT) if rank == 0 else EXIT_BAD_INPUT
    install_abort_hook(comm)
    from pmpm.runner import Run
    paths = []
    for scene in scenes:
        try:
            run = Run(scene, comm, restart=args.restart)
        except ConfigError as exc:
            return _bad_input(exc, args.case, rank)
        except OutputWriteError as exc:
            return _fail(str(exc), EXIT_WRITE_FAILED) if rank == 0 else EXIT_WRITE_FAILED
        except (FileNotFoundError, ValueError, OSError) as exc:
            if args.restart:
                return _fail(f"{args.restart}: cannot restart ({exc})", EXIT_BAD_INPUT) if rank == 0 else EXIT_BAD_INPUT
            raise
        try:
            summary = run.execute()
        except (UnstableRunError, ParticleExitError) as exc:
            return _fail(f"{args.case}: {exc}", EXIT_RUN_FAILED) if rank == 0 else EXIT_RUN_FAILED
        except OutputWriteError as exc:
            return _fail(str(exc), EXIT_WRITE_FAILED) if rank == 0 else EXIT_WRITE_FAILED
        paths.append(summary["output"])
        if rank == 0:
            logger.info("done: %d steps in %.1f s wall -> %s", summary["steps"], summary["wall"], summary["output"])
    if rank == 0 and not args.no_plots:
        from pmpm.io.post import postprocess
        try:
            postprocess(scenes, paths)
        except OSError as exc:  # CSV and PNG writes: rank 0 only, the run's files are complete
            return _fail(f"{exc.filename or scenes[0].output.directory}: cannot write "
                         f"({exc.strerror or type(exc).__name__})", EXIT_WRITE_FAILED)
    return 0


def _quiet_warnings():
    """Keep Python's warnings off the terminal: numpy's floating-point warnings (overflow) are
    dropped, since pmpm checks every value it uses for being finite and says so in its own
    line; any other warning goes to the logger ``py.warnings``, which prints nothing."""
    import warnings
    import numpy as np
    np.seterr(all="ignore")
    warnings.filterwarnings("ignore", category=RuntimeWarning)
    logging.captureWarnings(True)
    logging.getLogger("py.warnings").propagate = False


def _with_command(argv):
    """``argv`` with ``run`` inserted unless it starts with a subcommand or a top-level option."""
    if argv and (argv[0] in SUBCOMMANDS or argv[0] in ("-h", "--help", "--version")):
        return argv
    return ["run", *argv]


def main(argv=None):
    """Entry point of the `pmpm` console script; returns (and exits with) the exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv:
        return _fail("no scene file or subcommand given (pmpm --help lists them)", EXIT_BAD_INPUT)
    if len(argv) == 1 and argv[0] in SUBCOMMANDS[1:] and os.path.isfile(argv[0]):
        return _fail(f"{argv[0]!r} is a subcommand; to run the file of that name: pmpm ./{argv[0]}",
                     EXIT_BAD_INPUT)
    if len(argv) == 1 and argv[0] in ("version", "help") and not os.path.exists(argv[0]):
        return _fail(f"{argv[0]}: no such scene file (did you mean pmpm --{argv[0]}?)", EXIT_BAD_INPUT)
    _quiet_warnings()
    from pmpm.core.implicit.linear_solver import command_line_options
    petsc, argv = command_line_options(argv)
    args, extra = build_parser().parse_known_args(_with_command(argv))
    if getattr(args, "driver_args", None) is not None:  # pmpm bench accuracy|peer: the driver parses them
        args.driver_args, extra = extra + args.driver_args, []
    args.petsc = petsc
    if extra:  # named after the subcommand, like every other bad argument
        return (_fail(f"{args.command}: unrecognized arguments: {' '.join(extra)}", EXIT_BAD_INPUT)
                if _rank_env() == 0 else EXIT_BAD_INPUT)
    if args.command == "run":
        return run_case(args)
    if args.command == "expand":
        return expand_case(args)
    return _tool(args)


def console():
    sys.exit(main())


if __name__ == "__main__":
    sys.exit(main())
