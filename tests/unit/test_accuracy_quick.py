"""``pmpm bench accuracy --quick``, run in-process through the command line into tmp_path
(about 70 s on this 2-vCPU machine when it is idle, two minutes when it is shared).

The quick sweep: the axial bar (against its exact solution, v0 = 1e-3, one period) with MUSL and
2 x 2 particles per cell at 10, 20, 40, 80 and 160 cells for the three B-spline bases, and the
elastic portal frame (first peak of the joint panel's sway) at 0.1 and 0.05 m cells for the three
bases against a cubic 0.025 m reference. See studies/accuracy.py and docs/accuracy.md.

Checks:

* the command writes accuracy.csv, accuracy.md and accuracy.png and ends with one JSON line;
* the observed convergence order on the bar (least-squares slope over the finest three cell
  sizes, MUSL, 2 x 2 particles) is at least 1.8 for quadratic and cubic B-splines;
* on the frame (the first peak of the joint's sway), cubic B-splines are at least as accurate as
  linear ones at every cell size of the sweep, and their advantage grows under refinement (the
  ratio of the errors falls from 0.1 to 0.05 m cells): cubic converges at second order while the
  linear basis keeps its cell-crossing error (docs/verification.md section 6). The comparison is
  made on the frame, not on the bar: with the bar's small amplitude no particle crosses a cell
  boundary, so the linear basis has none of its cell-crossing error there.

Both comparisons use the errors alone, which are deterministic. The comparison at equal *wall
time* that the command also prints (cubic is behind at the sweep's coarse end, an open finding of
docs/accuracy.md) depends on the machine's load, so it is reported, not asserted: a test of it
could only be a non-strict xfail, which can never fail.
"""
import json

import pytest

from pmpm.cli import main


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    import contextlib
    import io
    outdir = tmp_path_factory.mktemp("accuracy")
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(["bench", "accuracy", "--quick", "--outdir", str(outdir)])
    text = buf.getvalue()
    print(text)
    return {"code": code, "outdir": outdir, "stdout": text,
            "summary": json.loads(text.strip().splitlines()[-1])}


def test_quick_writes_table_plot_and_json(quick):
    assert quick["code"] == 0
    for name in ("accuracy.csv", "accuracy.md", "accuracy.png"):
        path = quick["outdir"] / name
        assert path.is_file() and path.stat().st_size > 0, name
    csv_lines = (quick["outdir"] / "accuracy.csv").read_text().strip().splitlines()
    assert csv_lines[0].startswith("problem,shape,ppc,scheme,cell_size")
    assert len(csv_lines) - 1 == quick["summary"]["runs"]
    assert (quick["outdir"] / "accuracy.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "convergence order (cubic" in quick["stdout"]
    assert quick["summary"]["reference"]["shape"] == "cubic"


@pytest.mark.parametrize("shape", ["quadratic", "cubic"])
def test_quadratic_and_cubic_converge_at_second_order(quick, shape):
    order = quick["summary"]["orders"][shape]
    assert order["order"] >= 1.8, order


def _frame_errors(quick):
    """{(shape, cell size): error of the first peak} of the frame rows of accuracy.csv."""
    import csv
    with open(quick["outdir"] / "accuracy.csv") as f:
        rows = [r for r in csv.DictReader(f) if r["problem"] == "frame" and r["error"] not in ("", None)]
    return {(r["shape"], float(r["cell_size"])): float(r["error"]) for r in rows
            if r["ppc"] == "2" and r["scheme"] == "musl"}


def test_cubic_at_least_as_accurate_as_linear_at_every_frame_resolution(quick):
    err = _frame_errors(quick)
    sizes = sorted({h for (shape, h) in err if shape == "linear"}, reverse=True)
    assert len(sizes) >= 2, err
    for h in sizes:
        assert err[("cubic", h)] <= err[("linear", h)], (h, err)


def test_cubic_pulls_ahead_of_linear_under_refinement(quick):
    """The ratio cubic / linear of the frame errors falls from the coarsest to the finest cell
    size of the sweep (second order against a stalling cell-crossing error)."""
    err = _frame_errors(quick)
    sizes = sorted({h for (shape, h) in err if shape == "linear"}, reverse=True)
    ratio = [err[("cubic", h)] / err[("linear", h)] for h in sizes]
    assert ratio[-1] < ratio[0], dict(zip(sizes, ratio))
