"""After a run: CSV time histories and plots (rank 0 only)."""
import logging
import os

import h5py
import numpy as np

from pmpm.io import ownership
from pmpm.io.hdf5 import read_history
from pmpm.io.layout import frame_fields
from pmpm.scene.names import deformed_png, track_csv
from pmpm.io.plot import scene_stem
from pmpm.io import plot_results
from pmpm.results.post import structural_outputs
from pmpm.io import plot_deformed

__all__ = ["write_history_csv", "postprocess"]
logger = logging.getLogger(__name__)


def _run(h5_path):
    """``<stem>[_<variant>]``: the results file's own stem names its post-processed files."""
    return os.path.splitext(os.path.basename(h5_path))[0]


def write_history_csv(h5_path, outdir):
    """One CSV per tracked point: ``<stem>[_<variant>]_history_<track>.csv`` with t, ux, uy,
    vx, vy (SI units)."""
    paths = []
    with h5py.File(h5_path, "r") as f, ownership.writing(scene_stem(h5_path)):
        if "history" not in f:
            return paths
        t, tracks, cols = read_history(f)
        for name, data in tracks.items():
            keep = [cols.index(c) for c in ("ux", "uy", "vx", "vy")]
            path = ownership.claim(os.path.join(outdir, track_csv(_run(h5_path), name)))
            np.savetxt(path, np.column_stack([t, data[:, keep]]), delimiter=",",
                       header="t,ux,uy,vx,vy", comments="", fmt="%.9g")
            paths.append(path)
    return paths


def postprocess(scenes, h5_paths):
    """CSV histories, history/energy plots of all variants (overlaid), each variant's
    deformed-shape plot. ``scenes`` and ``h5_paths`` correspond one to one."""
    outdir = scenes[0].output.directory
    made = []
    # one transaction: a foreign file met on the way takes back every file of this call
    with ownership.writing(scenes[0].stem):
        for path in h5_paths:
            made += write_history_csv(path, outdir)
        made += plot_results(h5_paths, outdir)
        for path in h5_paths:
            made += structural_outputs(path, outdir)
        for scene, path in zip(scenes, h5_paths):
            if scene.output.deformed_plot:
                made.append(_deformed(path, scene.output.deformed_plot, outdir))
    for p in made:
        logger.info("wrote %s", p)
    return made


def _deformed(h5_path, spec, outdir):
    """Deformed shape at the frame where the tracked displacement is largest."""
    with h5py.File(h5_path, "r") as f:
        times = f["frames/time"][:]
        ht, tracks, cols = read_history(f)
        u = np.abs(tracks[spec["track"]][:, cols.index(spec["component"])])
        t_peak = ht[int(np.argmax(u))]
        frame = int(np.argmin(np.abs(times - t_peak)))
        color = spec["color"] if spec["color"] in frame_fields(f) else "x"
    out = os.path.join(outdir, deformed_png(_run(h5_path)))
    plot_deformed(h5_path, frame, color, spec["scale"], out)
    return out
