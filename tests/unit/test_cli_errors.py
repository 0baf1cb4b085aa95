"""Bad scenes through the real command line: exit code 2, one line on stderr, nothing written.

Each case runs ``python -m pmpm.cli case.toml`` in its own empty directory (the default output
directory ``<stem>_results`` would appear there). Validation errors return before any numba
compilation; the body, boundary-box, load-box and mesh errors are found while the particles are
placed, still before any kernel runs, so every case takes about a second.
"""
import subprocess
import sys

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
