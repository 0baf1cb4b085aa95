"""Bad fracture input through the real command line: exit code 2, one line on stderr naming the
key, nothing written (the pattern of tests/unit/test_cli_errors.py).

Planted bugs each case was seen to catch: the ``eta`` / ``fracture_energy`` / ``length`` checks
of pmpm.physics.materials.fracture._positive relaxed to ``< 0`` (the zero cases pass silently,
then the run writes its output folder); Material.read_params not refusing ``fracture`` (the
elastic and neo-Hookean cases then fail on "unknown key" without naming fracture support);
``band_lstar``'s check for a characteristic length removed and its bound relaxed to 10 (the
without-l* case then dies in the build with a traceback, the above-one case runs).
"""
import subprocess
import sys

import pytest

BASE_TOML = """\
[grid]
cell_size = 0.5
cells = [8, 4]

[materials.steel]
type = "bilinear_vonmises"
E = 200e9
nu = 0.3
density = 7850.0
yield_stress = 355e6
hardening = 0.01

[materials.steel.fracture]
model = "void_growth"
eta = 2.6
fracture_energy = 1e5

[[bodies]]
shape = "rectangle"
material = "steel"
lower = [0.0, 0.0]
upper = [2.0, 1.0]

[solver]
end_time = 1e-6
"""

ELASTIC = 'type = "linear_elastic"\nE = 200e9\nnu = 0.3\ndensity = 7850.0\n'


def _with(old, new):
    def edit(text):
        assert old in text, old
        return text.replace(old, new)
    return edit


def _material(body):
    """The steel table replaced by ``body`` (fracture sub-table kept)."""
    start = BASE_TOML.index('type = "bilinear_vonmises"')
    end = BASE_TOML.index("[materials.steel.fracture]")
    return lambda text: text[:start] + body + "\n" + text[end:]


CASES = {
    "unknown-model": (_with('model = "void_growth"', 'model = "gurson"'),
                      "materials.steel.fracture.model: unknown fracture model 'gurson'; one of: void_growth"),
    "missing-model": (_with('model = "void_growth"\n', ""), "materials.steel.fracture.model: missing"),
    "negative-eta": (_with("eta = 2.6", "eta = -2.6"), "materials.steel.fracture.eta: must be > 0 (got -2.6)"),
    "zero-eta": (_with("eta = 2.6", "eta = 0"), "materials.steel.fracture.eta: must be > 0 (got 0)"),
    "zero-fracture-energy": (_with("fracture_energy = 1e5", "fracture_energy = 0.0"),
                             "materials.steel.fracture.fracture_energy: must be > 0 (got 0)"),
    "negative-fracture-energy": (_with("fracture_energy = 1e5", "fracture_energy = -1e5"),
                                 "materials.steel.fracture.fracture_energy: must be > 0 (got -100000)"),
    "negative-length": (_with("fracture_energy = 1e5", "fracture_energy = 1e5\nlength = -0.01"),
                        "materials.steel.fracture.length: must be > 0 (got -0.01)"),
    "zero-length": (_with("fracture_energy = 1e5", "fracture_energy = 1e5\nlength = 0"),
                    "materials.steel.fracture.length: must be > 0 (got 0)"),
    "negative-characteristic-length": (
        _with("fracture_energy = 1e5", "fracture_energy = 1e5\ncharacteristic_length = -0.002"),
        "materials.steel.fracture.characteristic_length: must be > 0 (got -0.002)"),
    "zero-band-cells": (_with("fracture_energy = 1e5", "fracture_energy = 1e5\nband_cells = 0"),
                        "materials.steel.fracture.band_cells: must be > 0 (got 0)"),
    "band-cells-and-length": (_with("fracture_energy = 1e5", "fracture_energy = 1e5\nband_cells = 1.5\nlength = 0.01"),
                              "materials.steel.fracture.band_cells: give either length"),
    "band-lstar-without-lstar": (_with("fracture_energy = 1e5", "fracture_energy = 1e5\nband_lstar = 0.45"),
                                 "materials.steel.fracture.band_lstar: needs characteristic_length"),
    "band-lstar-and-length": (_with("fracture_energy = 1e5", "fracture_energy = 1e5\ncharacteristic_length = 0.006"
                                    "\nband_lstar = 0.45\nlength = 0.01"),
                              "materials.steel.fracture.band_lstar: give either length"),
    "zero-band-lstar": (_with("fracture_energy = 1e5", "fracture_energy = 1e5\ncharacteristic_length = 0.006"
                              "\nband_lstar = 0"), "materials.steel.fracture.band_lstar: must be > 0 (got 0)"),
    "band-lstar-above-one": (_with("fracture_energy = 1e5", "fracture_energy = 1e5\ncharacteristic_length = 0.006"
                                   "\nband_lstar = 1.5"), "materials.steel.fracture.band_lstar: must be <= 1"),
    "text-eta": (_with("eta = 2.6", 'eta = "2.6"'), "materials.steel.fracture.eta: must be a finite number"),
    "unknown-key": (_with("eta = 2.6", "eta = 2.6\nalpha = 2.6"), "materials.steel.fracture.alpha: unknown key"),
    "not-a-table": (lambda t: t.replace("[materials.steel.fracture]\nmodel = \"void_growth\"\neta = 2.6\n"
                                        "fracture_energy = 1e5\n", "").replace("hardening = 0.01", "hardening = 0.01\nfracture = 3"),
                    "materials.steel.fracture: must be a table"),
    "elastic": (_material(ELASTIC), "materials.steel.fracture: 'linear_elastic' cannot fracture"),
    "neo-hookean": (_material(ELASTIC.replace("linear_elastic", "neo_hookean")),
                    "materials.steel.fracture: 'neo_hookean' cannot fracture"),
    "damage-without-fracture": (lambda t: t[:t.index("[materials.steel.fracture]")] + t[t.index("[[bodies]]"):]
                                + '\n[output]\nfields = ["x", "damage"]\n',
                                "output.fields: no particle field 'damage'"),
}


@pytest.mark.parametrize("name", list(CASES))
def test_bad_fracture_input(tmp_path, name):
    edit, expected = CASES[name]
    case = tmp_path / "case.toml"
    case.write_text(edit(BASE_TOML))
    proc = subprocess.run([sys.executable, "-m", "pmpm.cli", str(case)], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, (proc.returncode, proc.stdout, proc.stderr)
    lines = proc.stderr.splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith(f"pmpm: error: {case}: "), lines[0]
    assert expected in lines[0], lines[0]
    assert [p.name for p in tmp_path.iterdir()] == ["case.toml"]   # nothing written
