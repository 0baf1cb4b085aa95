"""Plots from small synthetic results files (serial): files exist and are PNGs."""

import os

import numpy as np
import pytest
from mpi4py import MPI

from pmpm.io import OutputFile, energy_balance_error, plot_deformed, plot_results

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
N_TOTAL = 12
FRAME_FIELDS = {"x": ((2,), "f8"), "stress": ((4,), "f8"), "eps_p_eq": ((), "f8")}
ENERGY_COLUMNS = ["time", "kinetic", "strain_energy", "plastic_work", "external_work", "total"]


def make_results(path, variant, amplitude):
    """A tiny run: a swaying block, two tracks, energies that balance exactly."""
    ids = np.arange(N_TOTAL)
    x0 = np.stack([ids % 4, ids // 4], axis=1).astype(float)
    times = np.linspace(0.0, 1.0, 21)
    with OutputFile(path, MPI.COMM_SELF, {"scene": {"case": "block"}, "variant": variant}, N_TOTAL,
                    FRAME_FIELDS, ["tip", "base"], ["ux", "uy"], ENERGY_COLUMNS) as out:
        for frame, t in enumerate(times[::10]):
            sway = amplitude * np.sin(2 * np.pi * t) * x0[:, 1:2] * np.array([[1.0, 0.0]])
            out.write_frame(t, frame, {"id": ids, "x": x0 + sway, "stress": np.outer(x0[:, 1], [1, 2, 3, 4]),
                                       "eps_p_eq": 1e-3 * ids * t})
        u = amplitude * np.sin(2 * np.pi * times)
        out.write_history(times, {"tip": np.stack([u, 0 * u], 1), "base": np.stack([0.1 * u, 0 * u], 1)})
        for t, ui in zip(times, u):
            kinetic, strain, work = ui**2, 1.0 - ui**2, 0.5 * t
            out.write_energies({"time": t, "kinetic": kinetic, "strain_energy": strain, "plastic_work": work,
                                "external_work": work, "total": kinetic + strain})
    return str(path)


def is_png(path):
    with open(path, "rb") as fh:
        return os.path.getsize(path) > 1000 and fh.read(8) == PNG_MAGIC


def test_plot_results_overlays_variants(tmp_path):
    files = [make_results(tmp_path / "el.h5", "elastic", 0.01),
             make_results(tmp_path / "ep.h5", "elastoplastic", 0.02)]
    pngs = plot_results(files, tmp_path / "plots")
    names = sorted(os.path.basename(p) for p in pngs)
    # the history plots carry the first file's stem (no scene_file attribute here), the
    # energies each file's own
    assert names == ["el_energies.png", "el_history_base.png", "el_history_tip.png",
                     "ep_energies.png"]
    assert all(is_png(p) for p in pngs)


@pytest.mark.parametrize("color", ["eps_p_eq", "sxx", "stress"])
def test_plot_deformed(tmp_path, color):
    h5 = make_results(tmp_path / "el.h5", "elastic", 0.01)
    out = plot_deformed(h5, -1, color, 50.0, tmp_path / "shape" / f"{color}.png")
    assert is_png(out)


def test_plot_deformed_unknown_field(tmp_path):
    h5 = make_results(tmp_path / "el.h5", "elastic", 0.01)
    with pytest.raises(KeyError, match="nope"):
        plot_deformed(h5, 0, "nope", 1.0, tmp_path / "x.png")


def test_energy_balance_error():
    t = np.linspace(0, 1, 5)
    balanced = {"time": t, "kinetic": 1 - t, "strain_energy": t, "plastic_work": t, "external_work": t}
    np.testing.assert_allclose(energy_balance_error(balanced), 0.0, atol=1e-15)
    drifting = dict(balanced, kinetic=1 - t + 0.1 * t)
    # stored energy peaks at 0.1 + 1 + 1 = 2.1 at the end
    np.testing.assert_allclose(energy_balance_error(drifting)[-1], 0.1 / 2.1)
    assert energy_balance_error({"time": t}) is None
    # internal_work (strain + dissipation) replaces the separate terms when present
    with_internal = {"time": t, "kinetic": 1 - t, "strain_energy": 0 * t, "plastic_work": 5 * t,
                     "internal_work": t, "external_work": 0 * t}
    np.testing.assert_allclose(energy_balance_error(with_internal), 0.0, atol=1e-15)


@pytest.fixture
def figures(monkeypatch):
    """Every figure pmpm saves, kept (after drawing) for inspection."""
    from matplotlib.figure import Figure
    saved, original = [], Figure.savefig

    def keep(self, *args, **kwargs):
        original(self, *args, **kwargs)  # draws: the layout below is the final one
        saved.append(self)

    monkeypatch.setattr(Figure, "savefig", keep)
    return saved



def test_axes_have_units_and_legends_cover_no_curve(tmp_path, figures):
    files = [make_results(tmp_path / "el.h5", "elastic", 0.01),
             make_results(tmp_path / "ep.h5", "elastoplastic", 0.02)]
    plot_results(files, tmp_path / "plots")
    plot_deformed(files[0], -1, "sxx", 50.0, tmp_path / "shape.png")
    assert len(figures) == 5
    legends = 0
    for fig in figures:
        renderer = fig._get_renderer()
        for ax in fig.axes:
            if ax.get_label() == "<colorbar>":
                assert ax.get_ylabel() == "sxx (Pa)"
                continue
            # every y axis says its unit; x axes too where they are labelled (shared x: the bottom)
            assert ax.get_ylabel().endswith(")"), ax.get_ylabel()
            assert ax.get_xlabel() in ("", "time (s)", "x (m)"), ax.get_xlabel()
            legend = ax.get_legend()
            if legend is not None:
                legends += 1
                box, area = legend.get_window_extent(renderer), ax.get_window_extent(renderer)
                # the legend lies right of the axes, so it overlaps no curve drawn inside them
                assert box.x0 >= area.x1, (box, area)
        assert any(ax.get_xlabel() for ax in fig.axes)
    assert legends == 6  # two history plots, two energy plots (energies; balance error and loss)
