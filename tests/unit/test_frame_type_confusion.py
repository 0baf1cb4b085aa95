"""A [frame] scene whose own lists (bodies, boundary, loads.forces, output.section,
output.track) are not lists of tables: one line naming the entry, through the parser, ``pmpm
expand`` and ``pmpm case.toml --check`` alike (issue 35). Before the check in
pmpm.scene.frame.expand_frame these raised TypeError ('int' object is not iterable, argument
of type 'bool' is not iterable): this test failed on all 25 parser cases."""
import copy
import os
import subprocess
import sys

import pytest

from pmpm.errors import ConfigError
from pmpm.scene.config import parse_scene, read_toml
from pmpm.scene.frame import expand_frame

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PORTAL = os.path.join(ROOT, "cases", "portal_frame.toml")


def _with(key, value):
    data = read_toml(PORTAL)
    data.pop("variants")
    node = data
    for part in key.split(".")[:-1]:
        node = node.setdefault(part, {})
    node[key.split(".")[-1]] = value
    return data


@pytest.mark.parametrize("key", ["bodies", "boundary", "loads.forces", "output.section", "output.track"])
@pytest.mark.parametrize("value", [3, [1, 2], True, [True], [{"name": "x"}, 3]])
def test_a_list_of_tables_that_is_not(key, value):
    data = _with(key, value)
    for fn in (expand_frame, parse_scene):
        with pytest.raises(ConfigError) as exc:
            fn(copy.deepcopy(data))
        assert exc.value.key.startswith(key) and "\n" not in str(exc.value)


@pytest.mark.parametrize("command", [["expand"], ["--check"]])
def test_through_the_command_line(tmp_path, command):
    scene = tmp_path / "frame.toml"
    text = open(PORTAL).read().split("[variants", 1)[0]
    scene.write_text(text + "\n[output]\ntrack = 3\n" if "[output]" not in text else
                     text.replace("[output]", "[output]\ntrack = 3", 1))
    args = [sys.executable, "-m", "pmpm.cli"] + (["expand", str(scene)] if command == ["expand"]
                                                 else [str(scene), "--check"])
    r = subprocess.run(args, capture_output=True, text=True, env=dict(os.environ, PYTHONPATH=ROOT), timeout=300)
    assert r.returncode == 2, (r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "output.track" in lines[0], r.stderr
