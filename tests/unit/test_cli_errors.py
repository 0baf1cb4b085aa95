"""Bad scenes through the real command line: exit code 2, one line on stderr, nothing written.

Each case runs ``python -m pmpm.cli case.toml`` in its own empty directory (the default output
directory ``<stem>_results`` would appear there). Validation errors return before any numba
compilation; the body, boundary-box, load-box and mesh errors are found while the particles are
placed, still before any kernel runs, so every case takes about a second.
"""
import subprocess
import sys

import numpy as np
import pytest

BASE_TOML = """\
[grid]
cell_size = 0.5
cells = [8, 4]

[materials.steel]
type = "linear_elastic"
E = 100.0
nu = 0.3
density = 1.0

[[bodies]]
shape = "rectangle"
material = "steel"
lower = [0.0, 0.0]
upper = [2.0, 1.0]

[solver]
end_time = 0.01
"""

EXIT_BAD_INPUT = 2


def replace(old, new):
    def edit(text):
        assert old in text, old
        return text.replace(old, new)
    return edit


def prepend(extra):
    """Top-level keys must come before the first [table] header in TOML."""
    return lambda text: extra + "\n" + text


def append(extra):
    return lambda text: text + "\n" + extra + "\n"


def drop_section(header, upto):
    """Remove the lines from ``header`` up to (not including) ``upto``."""
    def edit(text):
        start = text.index(header)
        end = text.index(upto, start + len(header)) if upto else len(text)
        return text[:start] + text[end:]
    return edit


#: id -> (edit of BASE_TOML, what the single stderr line must contain)
CASES = {
    "unknown-top-level-key": (prepend('titel = "beam"'), "case.toml: titel: unknown key"),
    "unknown-key-in-section": (append("cfl_number = 0.4"), "case.toml: solver.cfl_number: unknown key"),
    "unknown-material-key": (replace("density = 1.0", "density = 1.0\nyoung = 3.0"),
                             "case.toml: materials.steel.young: unknown key"),
    "wrong-type": (replace("cell_size = 0.5", 'cell_size = "0.5"'), "case.toml: grid.cell_size: must be a finite number"),
    "missing-grid": (drop_section("[grid]", "[materials.steel]"), "case.toml: grid: missing"),
    "missing-materials": (drop_section("[materials.steel]", "[[bodies]]"), "case.toml: materials: missing"),
    "missing-bodies": (drop_section("[[bodies]]", "[solver]"), "case.toml: bodies: missing"),
    "missing-end-time": (replace("end_time = 0.01", "cfl = 0.4"), "case.toml: solver.end_time: missing"),
    "zero-density": (replace("density = 1.0", "density = 0"), "case.toml: materials.steel.density: must be > 0"),
    "nu-half": (replace("nu = 0.3", "nu = 0.5"), "case.toml: materials.steel.nu: must be < 0.5 (got 0.5)"),
    "nu-below-minus-one": (replace("nu = 0.3", "nu = -1.2"), "case.toml: materials.steel.nu: must be > -1 (got -1.2)"),
    "cfl-above-one": (replace("end_time = 0.01", "end_time = 0.01\ncfl = 1.5"),
                      "case.toml: solver.cfl: must be <= 1 (got 1.5)"),
    "unknown-objective-rate": (replace("end_time = 0.01", 'end_time = 0.01\nobjective_rate = "truesdell"'),
                               "case.toml: solver.objective_rate: must be one of jaumann, green_naghdi"),
    "rate-without-rotations": (replace("end_time = 0.01", 'end_time = 0.01\nobjective_rate = "green_naghdi"\n'
                                                          'large_rotations = false'),
                               "case.toml: solver.objective_rate: needs large_rotations = true"),
    "undefined-material": (replace('material = "steel"', 'material = "stel"'), "case.toml: bodies[0].material: no material 'stel'"),
    "output-field-typo": (append('[output]\nfields = ["x", "stres"]'), "case.toml: output.fields: no particle field 'stres'"),
    "malformed-toml": (replace("E = 100.0", "E = 100.0.0"), "case.toml: not valid TOML"),
    "variant-override": (append('[variants.soft]\n"materials.steel.E" = -5.0'),
                         "case.toml: materials.steel.E: must be > 0 (got -5)"),
    # found while the particles are placed
    "body-outside-grid": (replace("upper = [2.0, 1.0]", "upper = [5.0, 1.0]"), "case.toml: bodies[0]: lies outside the grid"),
    "boundary-box-no-node": (append('[[boundary]]\ntype = "fixed"\nlower = [0.1, 0.1]\nupper = [0.2, 0.2]'),
                             "case.toml: boundary[0]: box selects no grid node"),
    "load-box-no-particle": (append('[[loads.forces]]\nlower = [3.0, 0.0]\nupper = [4.0, 2.0]\nforce = [0.0, -1.0]'),
                             "case.toml: loads.forces[0]: box selects no particle"),
}


def run_cli(tmp_path, *args):
    return subprocess.run([sys.executable, "-m", "pmpm.cli", *args], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)


def assert_one_line_error(proc, expected):
    assert proc.returncode == EXIT_BAD_INPUT, (proc.returncode, proc.stdout, proc.stderr)
    lines = proc.stderr.splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("pmpm: error: "), lines[0]
    assert expected in lines[0], lines[0]
    return lines[0]


@pytest.mark.parametrize("name", list(CASES))
def test_bad_scene(tmp_path, name):
    edit, expected = CASES[name]
    case = tmp_path / "case.toml"
    case.write_text(edit(BASE_TOML))
    line = assert_one_line_error(run_cli(tmp_path, str(case)), expected)
    assert line.startswith(f"pmpm: error: {case}: ")
    assert [p.name for p in tmp_path.iterdir()] == ["case.toml"]


def test_message_format(tmp_path):
    (tmp_path / "case.toml").write_text(BASE_TOML.replace("E = 100.0", "E = -1"))
    proc = run_cli(tmp_path, "case.toml")
    assert proc.returncode == EXIT_BAD_INPUT
    assert proc.stderr == "pmpm: error: case.toml: materials.steel.E: must be > 0 (got -1)\n"
    assert [p.name for p in tmp_path.iterdir()] == ["case.toml"]


def test_garbage_mesh_file(tmp_path):
    (tmp_path / "part.msh").write_bytes(b"this is not a mesh\n$MeshFormat\nnonsense\n")
    case = tmp_path / "case.toml"
    case.write_text(BASE_TOML.replace('shape = "rectangle"', 'shape = "mesh"')
                    .replace("lower = [0.0, 0.0]\nupper = [2.0, 1.0]", 'file = "part.msh"'))
    proc = run_cli(tmp_path, str(case))
    line = assert_one_line_error(proc, "cannot read mesh")
    assert line.startswith(f"pmpm: error: {tmp_path / 'part.msh'}: ")
    assert proc.stdout == ""  # meshio's own complaints are folded into the one line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["case.toml", "part.msh"]


def test_missing_scene_file(tmp_path):
    assert_one_line_error(run_cli(tmp_path, "nope.toml"), "nope.toml: cannot read")
    assert list(tmp_path.iterdir()) == []


def test_unknown_variant(tmp_path):
    case = tmp_path / "case.toml"
    case.write_text(BASE_TOML + "\n[variants.soft]\n\"materials.steel.E\" = 50.0\n")
    assert_one_line_error(run_cli(tmp_path, str(case), "--variant", "hard"), "variants: no variant 'hard'")
    assert [p.name for p in tmp_path.iterdir()] == ["case.toml"]


def test_check_of_a_valid_scene_writes_nothing(tmp_path):
    case = tmp_path / "case.toml"
    case.write_text(BASE_TOML + "\n[variants.a]\n[variants.b]\nsolver.cfl = 0.3\n")
    proc = run_cli(tmp_path, str(case), "--check")
    assert proc.returncode == 0, proc.stderr
    assert "valid (2 run(s))" in proc.stdout and proc.stderr == ""
    assert [p.name for p in tmp_path.iterdir()] == ["case.toml"]


# -- command-line conventions: subcommands, --version, python -m pmpm, tool errors ---------------
def run_pmpm(tmp_path, *args):
    """``python -m pmpm`` (pmpm/__main__.py), the way a user without the console script runs it."""
    return subprocess.run([sys.executable, "-m", "pmpm", *args], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)


def test_version(tmp_path):
    import pmpm
    proc = run_pmpm(tmp_path, "--version")
    assert proc.returncode == 0 and proc.stdout == f"pmpm {pmpm.__version__}\n", proc


def test_help_lists_subcommands_and_every_option_has_help():
    import argparse

    from pmpm.cli import SUBCOMMANDS, build_parser

    parser = build_parser()
    text = parser.format_help()
    assert all(name in text for name in SUBCOMMANDS)

    def walk(p, where):
        for action in p._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, child in action.choices.items():
                    yield from walk(child, f"{where} {name}")
            elif not isinstance(action, argparse._HelpAction):
                yield where, action

    missing = [f"{where} {'/'.join(a.option_strings) or a.dest}" for where, a in walk(parser, "pmpm")
               if not a.help or a.help == argparse.SUPPRESS]
    assert missing == []


def test_a_file_named_like_a_subcommand_runs_with_a_path(tmp_path):
    (tmp_path / "plot").write_text(BASE_TOML)
    proc = run_pmpm(tmp_path, "./plot", "--check")
    assert proc.returncode == 0 and "./plot: valid (1 run(s))" in proc.stdout, proc.stderr
    # the bare name is the subcommand: one line saying how to run the file instead
    assert_one_line_error(run_pmpm(tmp_path, "plot"), "pmpm ./plot")


@pytest.fixture
def not_results(tmp_path):
    """Files a user might hand to plot/export by mistake: text, an HDF5 file of another program."""
    import h5py
    (tmp_path / "notes.h5").write_text("not hdf5\n")
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f["data"] = [1.0, 2.0]
    with h5py.File(tmp_path / "old.h5", "w") as f:  # the layout before units and strain_energy
        f.attrs["layout"] = "pmpm-results-1"
    # a pmpm results file without positions: nothing to draw or export
    from mpi4py import MPI

    from pmpm.io import OutputFile
    with OutputFile(tmp_path / "nox.h5", MPI.COMM_SELF, {}, 2, {"m": ((), "f8")}, [], [], ["time"]) as out:
        out.write_frame(0.0, 0, {"id": np.arange(2), "m": np.ones(2)})
    return tmp_path


@pytest.mark.parametrize("args, expected", [
    (["plot", "notes.h5"], "notes.h5: not an HDF5 file"),
    (["plot", "other.h5"], "other.h5: not a pmpm results file"),
    (["plot", "missing.h5"], "missing.h5: no such file"),
    (["plot", "old.h5"], "old.h5: results layout 'pmpm-results-1', this pmpm reads 'pmpm-results-3', 'pmpm-results-2'"),
    (["export", "notes.h5"], "notes.h5: not an HDF5 file"),
    (["export", "other.h5", "--format", "xdmf"], "other.h5: not a pmpm results file"),
    (["export", "missing.h5", "--format", "vtu"], "missing.h5: no such file"),
    (["export", "other.h5", "--format", "vtk"], "export: argument --format: invalid choice"),
    (["export", "nox.h5"], "nox.h5: has no /frames/x"),
    (["export", "nox.h5", "--format", "xdmf", "-o", "side"], "nox.h5: has no /frames/x"),
    (["export"], "export: the following arguments are required"),
    (["plot", "other.h5", "--outdir"], "plot: argument -o/--outdir: expected one argument"),
    (["bench", "throughput", "--particles", "0"], "bench throughput: argument --particles: must be >= 1"),
    (["bench", "scaling", "--steps", "many"], "bench scaling: argument --steps: not an integer"),
    (["bench", "nope"], "bench: argument bench: invalid choice"),
    (["case.toml", "--variant"], "run: argument --variant: expected one argument"),
    ([], "no scene file or subcommand given"),
    (["version"], "version: no such scene file (did you mean pmpm --version?)"),
])
def test_bad_tool_arguments(not_results, args, expected):
    before = sorted(p.name for p in not_results.iterdir())
    assert_one_line_error(run_pmpm(not_results, *args), expected)
    assert sorted(p.name for p in not_results.iterdir()) == before
