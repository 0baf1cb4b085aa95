"""Bad input for the implicit integrator through the real command line: one line naming the key,
exit code 2, nothing written (docs/implicit.md, "What is refused").

Shown to fail on planted bugs (restored): the PETSc options left unchecked (validate_options
not called: the misspelt option runs, exit 0, files written), and the contact refusal removed
(the run starts and fails inside the step with a traceback, not exit 2). The load-factor
control's scene check (options._check_static) not called: the static-no-load, -unknown-pattern
and -point-outside cases run past the parse (not exit 2 with the key).
"""
import subprocess
import sys

import pytest

from pmpm.scene.fingerprint import first_difference

BASE = """\
[grid]
cell_size = 0.5
cells = [8, 4]

[materials.steel]
type = "linear_elastic"
E = 100.0
nu = 0.3
density = 1.0

[[bodies]]
name = "block"
shape = "rectangle"
material = "steel"
lower = [0.0, 0.0]
upper = [2.0, 1.0]

[[boundary]]
type = "fixed"
lower = [0.0, 0.0]
upper = [0.0, 2.0]

[solver]
integrator = "implicit"
time_step = 0.01
end_time = 0.02
"""


PUSHOVER = """
[[boundary]]
name = "push"
type = "roller_y"
lower = [2.0, 0.0]
upper = [2.0, 1.0]

[pushover]
boundary = "push"
displacement = 0.01
control = "tip"

[[output.track]]
name = "tip"
point = [2.0, 0.5]
"""


#: [solver.static] after BASE's [solver] table ({analysis}: the key that makes it static)
STATIC = """{analysis}
[solver.static]
control = "{control}"
{keys}
"""
STATIC_ANALYSIS = 'analysis = "static"'
#: a force set for the pattern
FORCE = """
[[loads.forces]]
name = "tip"
body = "block"
force = [0.0, -1.0]
"""


def _edit(old, new):
    def edit(text):
        assert old in text, old
        return text.replace(old, new)
    return edit


def _append(extra):
    return lambda text: text + extra + "\n"


#: id -> (edit of BASE, extra command-line arguments, what the one stderr line must say)
CASES = {
    "unknown-integrator": (_edit('integrator = "implicit"', 'integrator = "implict"'), [],
                           "solver.integrator: must be one of explicit, implicit"),
    "negative-tolerance": (_append("[solver.implicit]\nresidual_tolerance = -1e-8"), [],
                           "solver.implicit.residual_tolerance: must be > 0"),
    "unknown-newton-variant": (_append('[solver.implicit]\nnewton = "quasi"'), [],
                               "solver.implicit.newton: must be one of full, modified, krylov"),
    # newton = "krylov"'s GMRES (pmpm/core/implicit/kept_factorisation.py)
    "krylov-tolerance-not-below-one": (_append('[solver.implicit]\nnewton = "krylov"\nkrylov_tolerance = 1.0'), [],
                                       "solver.implicit.krylov_tolerance: must be < 1"),
    "krylov-iterations-zero": (_append('[solver.implicit]\nnewton = "krylov"\nkrylov_iterations = 0'), [],
                               "solver.implicit.krylov_iterations: must be >= 1"),
    "krylov-key-without-krylov": (_append('[solver.implicit]\nnewton = "modified"\nkrylov_iterations = 20'), [],
                                  "solver.implicit.krylov_iterations: sets the GMRES of newton = \"krylov\""),
    "unknown-implicit-key": (_append("[solver.implicit]\ntolerance = 1e-8"), [], "solver.implicit.tolerance: unknown key"),
    "unknown-petsc-option": (_append("[solver.petsc]\nksp_tpye = \"cg\""), [],
                             "solver.petsc.ksp_tpye: PETSc did not use this option"),
    "not-a-solver-option": (_append("[solver.petsc]\nsnes_type = \"newtonls\""), [],
                            "solver.petsc.snes_type: not a PETSc linear-solver option"),
    "unknown-petsc-option-on-command-line": (lambda t: t, ["-pc_tpye", "jacobi"],
                                             "solver.petsc.pc_tpye: PETSc did not use this option"),
    "petsc-options-on-an-explicit-scene": (_edit('integrator = "implicit"\ntime_step = 0.01', ""), ["-ksp_type", "cg"],
                                           "solver.petsc: is the implicit integrator's"),
    "missing-time-step": (_edit("time_step = 0.01\n", ""), [], "solver.time_step: required by the implicit integrator"),
    "explicit-scheme": (_append('scheme = "usl"'), [], "solver.scheme: is the explicit integrator's"),
    "static-explicit": (_edit('integrator = "implicit"\ntime_step = 0.01', 'analysis = "static"'), [],
                        "solver.analysis: static analyses need solver.integrator = \"implicit\""),
    "contact": (_append("[contact]\nfriction = 0.0"), [], "contact: is explicit-only for now"),
    "cpdi": (_append('interpolation = "cpdi"'), [], "solver.interpolation: GIMP and CPDI are explicit-only"),
    "damping": (_append("[loads]\ndamping = 2.0"), [], "damping: is explicit-only for now"),
    # the parts refuse themselves (implicit_support): a transfer, and an effect of the results layer
    "apic": (_append('transfer = "apic"'), [], "solver.transfer: apic: the implicit step updates velocities"),
    # a pushover is static only under the implicit integrator (its nodes' displacement is
    # prescribed per static step; the dynamic push's velocity profile is not carried yet)
    "pushover-dynamic": (lambda t: _append(PUSHOVER)(t.replace('type = "fixed"', 'name = "wall"\ntype = "fixed"\n'
                                                               'reaction = true')), [],
                         "pushover: is static only under the implicit integrator"),
    "initial-static-in-statics": (_append('analysis = "static"\n[solver.implicit]\ninitial_static = true'), [],
                                  "solver.implicit.initial_static: starts a dynamic analysis from static equilibrium"),
    "neo-hookean": (_edit('type = "linear_elastic"', 'type = "neo_hookean"'), [],
                    "materials.steel.type: neo_hookean has no tangent for the implicit integrator yet"),
    # load-factor control ([solver.static], pmpm/core/implicit/arclength.py)
    "static-control-in-dynamics": (_append(STATIC.format(analysis="", control="arc_length",
                                                         keys="load_factor_increment = 0.1")), [],
                                   "solver.static: drives a static analysis"),
    "static-unknown-control": (_append(STATIC.format(analysis=STATIC_ANALYSIS, control="arc", keys="")), [],
                               "solver.static.control: must be one of load, displacement, arc_length"),
    "static-negative-increment": (_append(STATIC.format(analysis=STATIC_ANALYSIS, control="arc_length",
                                                        keys="load_factor_increment = -0.1") + FORCE), [],
                                  "solver.static.load_factor_increment: must be > 0"),
    "static-no-point": (_append(STATIC.format(analysis=STATIC_ANALYSIS, control="displacement",
                                              keys='component = "y"\ndisplacement = -0.01') + FORCE), [],
                        "solver.static.point: missing (required)"),
    "static-zero-displacement": (_append(STATIC.format(analysis=STATIC_ANALYSIS, control="displacement",
                                                       keys='point = [2.0, 0.5]\ncomponent = "y"\ndisplacement = 0.0')
                                         + FORCE), [], "solver.static.displacement: must not be zero"),
    "static-point-outside": (_append(STATIC.format(analysis=STATIC_ANALYSIS, control="displacement",
                                                   keys='point = [9.0, 0.5]\ncomponent = "y"\ndisplacement = -0.01')
                                     + FORCE), [], "solver.static.point: [9.0, 0.5] lies outside the grid"),
    "static-unknown-key": (_append(STATIC.format(analysis=STATIC_ANALYSIS, control="arc_length",
                                                 keys="load_factor_increment = 0.1\narc = 0.1") + FORCE), [],
                           "solver.static.arc: unknown key"),
    "static-no-load": (_append(STATIC.format(analysis=STATIC_ANALYSIS, control="arc_length",
                                             keys="load_factor_increment = 0.1")), [],
                       "solver.static.pattern: no load to scale"),
    "static-unknown-pattern": (_append(STATIC.format(analysis=STATIC_ANALYSIS, control="arc_length",
                                                     keys='load_factor_increment = 0.1\npattern = ["floor"]') + FORCE),
                               [], "solver.static.pattern: no [[loads.forces]] named 'floor' (defined: tip)"),
    "static-gravity-pattern-without-gravity": (_append(STATIC.format(
        analysis=STATIC_ANALYSIS, control="arc_length", keys='load_factor_increment = 0.1\ngravity = "pattern"') + FORCE),
        [], "solver.static.gravity: is \"pattern\" but the scene has no loads.gravity"),
}


@pytest.mark.parametrize("name", list(CASES))
def test_bad_implicit_scene(tmp_path, name):
    edit, extra, expected = CASES[name]
    case = tmp_path / "case.toml"
    case.write_text(edit(BASE))
    proc = subprocess.run([sys.executable, "-m", "pmpm.cli", str(case), *extra], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, (proc.returncode, proc.stdout, proc.stderr)
    lines = proc.stderr.splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith(f"pmpm: error: {case}: "), lines[0]
    assert expected in lines[0], lines[0]
    assert [p.name for p in tmp_path.iterdir()] == ["case.toml"]


def test_a_good_implicit_scene_with_command_line_options_runs(tmp_path):
    """The same scene, valid, with a Krylov solver from the command line: exit 0."""
    case = tmp_path / "case.toml"
    case.write_text(BASE)
    proc = subprocess.run([sys.executable, "-m", "pmpm.cli", str(case), "--no-plots", "-ksp_type", "cg",
                           "-pc_type", "jacobi", "-ksp_rtol", "1e-12"], cwd=tmp_path, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "case_results" / "case.h5").exists()


def test_newton_failure_at_the_smallest_step_stops_with_exit_3(tmp_path):
    """A step Newton cannot converge (one iteration allowed, a tolerance below round-off, no
    halving) stops the run: exit 3, the message names Newton and max_halvings."""
    case = tmp_path / "case.toml"
    case.write_text(BASE.replace("[[boundary]]", "[loads]\ngravity = [0.0, -9.81]\n\n[[boundary]]")
                    + "[solver.implicit]\nmax_iterations = 1\nresidual_tolerance = 1e-30\nmax_halvings = 0\n")
    proc = subprocess.run([sys.executable, "-m", "pmpm.cli", str(case), "--no-plots"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 3, (proc.returncode, proc.stderr[-2000:])
    assert "Newton's method did not converge" in proc.stderr
    assert "solver.implicit.max_halvings = 0" in proc.stderr


def test_the_krylov_controls_may_change_on_restart_like_newton():
    """A run restarted from its last good state may switch ``newton`` (and so to "krylov"): the
    krylov mode's own controls must be changeable too, or the switch is refused as another
    scene. The answer they converge to is the same (to the tolerances)."""
    ours = {"solver.implicit.newton": "krylov", "solver.implicit.krylov_tolerance": 1e-6,
            "solver.implicit.krylov_iterations": 20, "solver.end_time": 1.0, "grid.cell_size": 0.1}
    theirs = {"solver.implicit.newton": "modified", "grid.cell_size": 0.1}
    assert first_difference(ours, theirs) is None
    assert first_difference(ours, dict(theirs, **{"grid.cell_size": 0.05})) == "grid.cell_size"
