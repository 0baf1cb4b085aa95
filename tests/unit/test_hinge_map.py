"""The hinge map of a frame with many cuts (pmpm/results/plots.py, plot_hinge_map): beyond
FULL_LABELS cuts the yielding cuts are numbered in the order they first reach My (hinge_rows'
order: Mp first, then My) and listed beside the map; cuts below My get a grey marker and no label.

Synthetic cuts with M(t) = a t (|M| reaches My = 1 at t = 1 / a), so the order is known in
closed form; the frame's outline is a few points in an HDF5 file like a run's."""
import h5py
import numpy as np

from pmpm.results import plots


def _sections(slopes):
    t = np.linspace(0.0, 1.0, 1001)
    out = {}
    for k, a in enumerate(slopes):
        out[f"cut_{k:02d}"] = {"time": t, "M": -a * t, "N": 0.0 * t,
                               "attrs": {"My": 1.0, "Mp": 1.5, "Np": 10.0, "center": [1.0 + k, 2.0 + 0.5 * k]}}
    return out


def _capture(monkeypatch):
    figures = []
    make = plots._figure

    def keep(**kw):
        figures.append(make(**kw))
        return figures[-1]
    monkeypatch.setattr(plots, "_figure", keep)
    return figures


def test_many_cuts_are_numbered_in_yield_order_and_listed(tmp_path, monkeypatch):
    h5 = tmp_path / "run.h5"
    with h5py.File(h5, "w") as f:
        f["frames/x0"] = np.random.default_rng(1).uniform(0, 12, (1, 50, 2))
    # 12 cuts: slopes 0.5 (never yields by t = 1) up to 4 (My at 0.25, Mp at 0.375); shuffled
    slopes = [0.5, 2.0, 0.8, 4.0, 1.25, 0.9, 3.0, 1.6, 0.6, 2.5, 0.7, 1.1]
    figures = _capture(monkeypatch)
    plots.plot_hinge_map(str(h5), _sections(slopes), str(tmp_path / "hinges.png"), "test")
    assert (tmp_path / "hinges.png").stat().st_size > 0
    fig = figures[-1]
    ax = fig.axes[0]
    numbers = {int(a.get_text()): tuple(a.xy) for a in ax.texts}
    # the cuts that reach My by t = 1 (slope >= 1), fastest first
    yielding = sorted((k for k, a in enumerate(slopes) if a >= 1.0), key=lambda k: -slopes[k])
    assert sorted(numbers) == list(range(1, len(yielding) + 1))
    for rank, k in enumerate(yielding, start=1):
        assert numbers[rank] == (1.0 + k, 2.0 + 0.5 * k)
    listing = fig.texts[0].get_text().splitlines()
    assert [line.split()[1] for line in listing[1:1 + len(yielding)]] == [f"cut_{k:02d}" for k in yielding]
    assert listing[-1] == f"{len(slopes) - len(yielding)} of {len(slopes)} cuts below My (grey)"


def test_few_cuts_keep_their_full_labels(tmp_path, monkeypatch):
    h5 = tmp_path / "run.h5"
    with h5py.File(h5, "w") as f:
        f["frames/x0"] = np.zeros((1, 4, 2))
    figures = _capture(monkeypatch)
    plots.plot_hinge_map(str(h5), _sections([2.0, 0.5]), str(tmp_path / "h.png"), "test")
    texts = [a.get_text() for a in figures[-1].axes[0].texts]
    assert texts[0].splitlines() == ["cut_00", "My at 500.0 ms", "Mp at 750.0 ms"]
    assert texts[1].splitlines() == ["cut_01", "My not reached", "Mp not reached"]
