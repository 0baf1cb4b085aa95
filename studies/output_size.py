"""The main job's output size in the results layout before issue 40 and now (docs/output.md).

Runs the main job's scene (cases/portal_frame.toml, both variants: 101 frames of x, x0, v,
stress, strain and, elastoplastic, eps_p_eq) at a cell size of the caller's choice, written at
``output.precision = "single"`` (the default) and ``"double"``, and writes each results file
again in the layout of pmpm before issue 40 (:func:`pmpm.io.legacy.write_layout2`: ids and x0 in
every frame, float64, uncompressed, with the sidecar's views; its size depends on the shapes only,
not on the values). Per file it prints the size of the whole results file (``os.path.getsize``,
what ``du --apparent-size`` shows) and of its particle data (frames and constants, as stored),
in bytes and per particle-frame; then the main job's resolution (0.025 m, its particle count
built from the case) extrapolated: the particle data per particle-frame (a coarser run has fewer
particles of the same kind in the same frames, so its bytes per particle-frame carry over; the
finer grid's smoother fields compress at least as well; the old layout's are exact by its shapes)
times the main job's particles and frames, plus the rest of the file as measured (histories,
energies, section and reaction tables, the views' metadata: they grow with the simulated time
and the frames, not with the particles).

Run (every rank runs the scene; rank 0 measures)::

    mpirun -n 2 python -m studies.output_size --cell 0.05
    python -m studies.output_size --cell 0.1            # a minute on one rank

Then the cost of writing a frame (rank 0 alone, ``OutputFile`` on one rank): the elastoplastic
double run's frames written again through the writer at each precision, with the compression
on and off (``pmpm.io.hdf5.COMPRESSION`` emptied), median wall time per frame.

The last line is one JSON object with every figure.
"""
import argparse
import json
import os
import shutil
import tempfile
import time

import h5py
import numpy as np
from mpi4py import MPI

import pmpm
from pmpm.build import build_solver
from pmpm.io import hdf5
from pmpm.io.layout import frame_fields
from pmpm.io.legacy import write_layout2
from pmpm.scene.config import load_scene

CASE = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "cases", "portal_frame.toml")
MAIN_CELL = 0.025
DOMAIN = ((-0.5, 6.6), (0.0, 4.2))   # the case's grid: x in [-0.5, 6.6], y in [0, 4.2]
VARIANTS = ("elastic", "elastoplastic")
PRECISIONS = ("single", "double")


def grid_overrides(cell):
    """The case's domain in cells of ``cell`` (m)."""
    cells = [int(round((hi - lo) / cell)) for lo, hi in DOMAIN]
    return {"grid.cell_size": float(cell), "grid.cells": cells, "grid.origin": [DOMAIN[0][0], DOMAIN[1][0]]}


def particle_bytes(path):
    """Bytes the particle data take in the file as stored: /frames/<field> but time and step,
    and /particles (the constants); views hold none."""
    total = 0
    with h5py.File(path, "r") as f:
        for group in ("frames", "particles"):
            for name, dset in f.get(group, {}).items():
                if name not in ("time", "step"):
                    total += dset.id.get_storage_size()
    return total


def measure(path, scratch):
    """Sizes of one results file and of its old-layout twin."""
    with h5py.File(path, "r") as f:
        frames, n = f["frames/time"].shape[0], int(f.attrs["n_total"])
    old = write_layout2(path, os.path.join(scratch, "old_" + os.path.basename(path)))
    out = {"particles": n, "frames": frames}
    for key, p in (("new", path), ("old", old)):
        out[f"{key}_file"] = os.path.getsize(p)
        out[f"{key}_particle_data"] = particle_bytes(p)
    os.remove(old)
    return out


def write_cost(path, scratch, precision, compress):
    """Median wall time (s) of OutputFile.write_frame replaying the frames of ``path``."""
    with h5py.File(path, "r") as f:
        fields = {n: d.read() for n, d in frame_fields(f).items()}
        times = f["frames/time"][()]
    n = fields["x"].shape[1]
    specs = {k: (v.shape[2:], np.float64 if v.dtype.kind == "f" else v.dtype) for k, v in fields.items()}
    saved = dict(hdf5.COMPRESSION)
    if not compress:
        hdf5.COMPRESSION.clear()
    target = os.path.join(scratch, f"cost_{precision}_{compress}.h5")
    walls = []
    try:
        with hdf5.OutputFile(target, MPI.COMM_SELF, {"scene": "{}"}, n, specs, [], [], ["time"],
                             precision=precision) as out:
            for k, t in enumerate(times):
                rows = {name: a[k].astype(specs[name][1]) for name, a in fields.items()}
                alive = rows["id"] >= 0
                rows = {name: a[alive] for name, a in rows.items()}
                start = time.perf_counter()
                out.write_frame(float(t), k, rows)
                walls.append(time.perf_counter() - start)
    finally:
        hdf5.COMPRESSION.update(saved)
    size = os.path.getsize(target)
    os.remove(target)
    return float(np.median(walls)), size


def main_job_particles():
    """The main job's particle count at its own resolution (built, not stepped)."""
    return {v: build_solver(load_scene(CASE, variant=v)[0], MPI.COMM_SELF).n_total for v in VARIANTS}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cell", type=float, default=0.05, help="cell size of the runs (m); the main job's is 0.025")
    ap.add_argument("--keep", help="keep the results files in this folder")
    args = ap.parse_args(argv)
    comm = MPI.COMM_WORLD
    scratch = comm.bcast(tempfile.mkdtemp(prefix="pmpm_output_size_") if comm.rank == 0 else None)
    rows = []
    for precision in PRECISIONS:
        over = dict(grid_overrides(args.cell), **{"output.directory": os.path.join(scratch, precision),
                                                  "output.precision": precision})
        results = pmpm.run(CASE, overrides=over, write=True, comm=comm, dataframes=False)
        if comm.rank == 0:
            for variant in VARIANTS:
                rows.append(dict(variant=variant, precision=precision, path=results[variant].path,
                                 **measure(results[variant].path, scratch)))
    if comm.rank != 0:
        return
    counts = main_job_particles()
    print(f"portal frame (cases/portal_frame.toml) at {args.cell} m cells on {comm.size} rank(s); "
          f"main job at {MAIN_CELL} m: {counts} particles, same frames")
    print(f"{'variant':14s} {'precision':9s} {'n':>7s} {'F':>4s} {'old file':>12s} {'new file':>12s} "
          f"{'old B/pf':>9s} {'new B/pf':>9s} {'ratio':>6s} {'main old MB':>11s} {'main new MB':>11s}")
    print("(file: whole results file, bytes; B/pf: particle data per particle and frame; ratio: old file / new "
          "file at this resolution; main: the main job's file, extrapolated)")
    summary = {"cell": args.cell, "ranks": comm.size, "main_cell": MAIN_CELL, "main_particles": counts,
               "rows": rows, "main_job": {}}
    for row in rows:
        per = row["particles"] * row["frames"]
        old_bpf, new_bpf = row["old_particle_data"] / per, row["new_particle_data"] / per
        main_n = counts[row["variant"]] * row["frames"]
        old_rest, new_rest = (row[f"{k}_file"] - row[f"{k}_particle_data"] for k in ("old", "new"))
        row.update(old_bytes_per_particle_frame=old_bpf, new_bytes_per_particle_frame=new_bpf,
                   ratio=row["old_file"] / row["new_file"], main_old_MB=(old_bpf * main_n + old_rest) / 1e6,
                   main_new_MB=(new_bpf * main_n + new_rest) / 1e6)
        print(f"{row['variant']:14s} {row['precision']:9s} {row['particles']:7d} {row['frames']:4d} "
              f"{row['old_file']:12d} {row['new_file']:12d} {old_bpf:9.2f} {new_bpf:9.2f} "
              f"{row['ratio']:6.2f} {row['main_old_MB']:11.1f} {row['main_new_MB']:11.1f}")
    for precision in PRECISIONS:
        chosen = [r for r in rows if r["precision"] == precision]
        old = sum(r["main_old_MB"] for r in chosen)
        new = sum(r["main_new_MB"] for r in chosen)
        summary["main_job"][precision] = {"old_MB": old, "new_MB": new, "ratio": old / new}
        print(f"main job, both variants, output.precision = {precision!r}: {old:.0f} MB before, "
              f"{new:.0f} MB after ({old / new:.2f}x smaller; extrapolated per particle-frame)")
    plastic = [r for r in rows if r["variant"] == "elastoplastic" and r["precision"] == "double"][0]
    source = plastic["path"]
    summary["write_ms_per_frame"] = {}
    for precision in PRECISIONS:
        for compress in (True, False):
            wall, size = write_cost(source, scratch, precision, compress)
            key = f"{precision}{'' if compress else ' uncompressed'}"
            summary["write_ms_per_frame"][key] = wall * 1e3
            print(f"writing a frame of {plastic['particles']} particles (elastoplastic, one rank): "
                  f"{key:20s} {wall * 1e3:7.2f} ms, file {size} bytes")
    if args.keep:
        shutil.copytree(scratch, args.keep, dirs_exist_ok=True)
    shutil.rmtree(scratch, ignore_errors=True)
    print(json.dumps(summary, default=lambda o: o.item() if isinstance(o, np.generic) else str(o)))


if __name__ == "__main__":
    main()
