#!/usr/bin/env python3
"""Gather ``pmpm bench scaling`` results into a scaling table and a plot.

Usage::

    python jobs/gather_scaling.py scaling_weak.jsonl [scaling_strong.jsonl ...] -o outdir

Each input file holds one JSON object per line, the last line of a
``mpirun -n K pmpm bench scaling ...`` run (``jobs/slurm_scaling_*.sh`` append them).
Blank lines and lines that are not JSON objects (e.g. a truncated line from a killed
job) are skipped with a warning on stderr.

Writes to ``outdir``:

``scaling.csv``
    one row per (series, ranks), every figure at full precision;
``scaling.md``
    the same as a Markdown table (also printed on stdout);
``scaling_efficiency.png``
    parallel efficiency against ranks (work efficiency solid, wall efficiency dashed).

Series
------
Rows are grouped into series by ``mode`` and problem size: the total particle count for
``strong`` runs, the particle count per rank for ``weak`` runs (the benchmark rounds the
block to whole cells, so sizes within 10 % count as the same series). When a file holds
several results for the same series and rank count (a sweep run twice, a requeued job),
the last one wins.

Figures
-------
work inflation
    sum over ranks of the CPU time spent computing / CPU time one rank needs for the same
    work (measured by the benchmark itself). 1.0 = no parallel overhead in computation.
work efficiency
    1 / work inflation (same figure, as an efficiency).
wall efficiency
    from the wall-clock throughput ``particle_steps_per_s`` (P) relative to the series'
    smallest rank count k0 (normally 1): ``(P_k / k) / (P_k0 / k0)``. For ``strong``
    series this is the classic speed-up / k; for ``weak`` series, where the work per rank
    is fixed, it is the time of k0 ranks over the time of k ranks. Meaningful only where
    every rank has a core of its own (not on a 2-vCPU machine; see docs/jobs.md).
halo / migration bytes per step
    mean over ranks of the bytes each rank sends per step.
"""
from __future__ import annotations

import argparse
import csv
import json
import math
import os
import sys

REQUIRED = ("ranks", "mode", "particles", "steps", "work_inflation", "particle_steps_per_s",
            "halo_bytes_per_step", "migration_bytes_per_step")

COLUMNS = [  # (key, Markdown header, Markdown format)
    ("series", "series", "{}"),
    ("mode", "mode", "{}"),
    ("ranks", "ranks", "{:d}"),
    ("particles", "particles", "{:d}"),
    ("particles_per_rank", "particles/rank", "{:.0f}"),
    ("steps", "steps", "{:d}"),
    ("work_inflation", "work inflation", "{:.3f}"),
    ("work_inflation_with_comm", "inflation incl. MPI time", "{:.3f}"),
    ("work_efficiency", "work efficiency", "{:.3f}"),
    ("wall_efficiency", "wall efficiency", "{:.3f}"),
    ("particle_steps_per_s", "particle-steps/s", "{:.3g}"),
    ("halo_bytes_per_step", "halo B/step", "{:.0f}"),
    ("migration_bytes_per_step", "migration B/step", "{:.0f}"),
    ("comm_s_per_step", "MPI s/step", "{:.2e}"),
]


def read_results(paths):
    """Return the result dicts of the JSON-lines files, in file and line order."""
    rows = []
    for path in paths:
        with open(path, encoding="utf-8") as fh:
            for lineno, line in enumerate(fh, 1):
                line = line.strip()
                if not line:
                    continue
                try:
                    obj = json.loads(line)
                except json.JSONDecodeError as exc:
                    print(f"gather_scaling: {path}:{lineno}: skipped, not JSON ({exc.msg})", file=sys.stderr)
                    continue
                if not isinstance(obj, dict):
                    print(f"gather_scaling: {path}:{lineno}: skipped, not a JSON object", file=sys.stderr)
                    continue
                missing = [k for k in REQUIRED if k not in obj]
                if missing:
                    raise ValueError(f"{path}:{lineno}: missing key(s) {', '.join(missing)}")
                obj["_source"] = f"{path}:{lineno}"
                rows.append(obj)
    return rows


def _size(row):
    """The size that defines a series: particles per rank (weak) or in total (strong)."""
    return row["particles"] / row["ranks"] if row["mode"] == "weak" else row["particles"]


def build_table(results):
    """Group into series, keep the last result per (series, ranks), add the efficiencies."""
    series = []  # [(mode, reference size, {ranks: row})]
    for r in results:
        size = _size(r)
        for mode, ref, by_ranks in series:
            if mode == r["mode"] and abs(size - ref) <= 0.1 * ref:
                break
        else:
            by_ranks = {}
            series.append((r["mode"], size, by_ranks))
        by_ranks[int(r["ranks"])] = r  # the last one wins
    table = []
    for mode, ref, by_ranks in series:
        name = f"{mode}, {ref:,.0f} particles" + (" per rank" if mode == "weak" else "")
        k0 = min(by_ranks)
        base = by_ranks[k0]["particle_steps_per_s"] / k0
        for k in sorted(by_ranks):
            r = by_ranks[k]
            infl = float(r["work_inflation"])
            table.append({
                "series": name, "mode": mode, "ranks": k, "particles": int(r["particles"]),
                "particles_per_rank": r["particles"] / k, "steps": int(r["steps"]),
                "work_inflation": infl,
                "work_inflation_with_comm": float(r.get("work_inflation_with_comm", math.nan)),
                "work_efficiency": 1.0 / infl if infl > 0 else math.nan,
                "wall_efficiency": (r["particle_steps_per_s"] / k) / base if base > 0 else math.nan,
                "wall_reference_ranks": k0,
                "particle_steps_per_s": float(r["particle_steps_per_s"]),
                "halo_bytes_per_step": float(r["halo_bytes_per_step"]),
                "migration_bytes_per_step": float(r["migration_bytes_per_step"]),
                "comm_s_per_step": float(r.get("comm_s_per_step", math.nan)),
                "one_rank_cpu_s": float(r.get("one_rank_cpu_s", math.nan)),
                "source": r["_source"],
            })
    return table


def write_csv(table, path):
    keys = [k for k, _, _ in COLUMNS] + ["wall_reference_ranks", "one_rank_cpu_s", "source"]
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=keys)
        w.writeheader()
        for row in table:
            w.writerow({k: (repr(row[k]) if isinstance(row[k], float) else row[k]) for k in keys})


def _fmt(fmt, value):
    if isinstance(value, float) and not math.isfinite(value):
        return "n/a"
    return fmt.format(value)


def markdown(table):
    lines = ["| " + " | ".join(h for _, h, _ in COLUMNS) + " |",
             "|" + "|".join("---" if k in ("series", "mode") else "---:" for k, _, _ in COLUMNS) + "|"]
    for row in table:
        lines.append("| " + " | ".join(_fmt(f, row[k]) for k, _, f in COLUMNS) + " |")
    note = ("\nWork efficiency = 1 / work inflation (CPU time of all ranks computing over the CPU time of "
            "one rank doing the same work). Wall efficiency = particle-steps/s per rank relative to")
    refs = {r["series"]: r["wall_reference_ranks"] for r in table}
    if all(k == 1 for k in refs.values()):
        note += " 1 rank."
    else:
        note += " the series' smallest rank count (" + "; ".join(f"{s}: {k}" for s, k in refs.items()) + ")."
    return "\n".join(lines) + "\n" + note + "\n"


def plot(table, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    names = list(dict.fromkeys(r["series"] for r in table))
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    all_ranks = sorted({r["ranks"] for r in table})
    for i, name in enumerate(names):
        rows = [r for r in table if r["series"] == name]
        k = [r["ranks"] for r in rows]
        c = colors[i % len(colors)]
        ax.plot(k, [r["work_efficiency"] for r in rows], "o-", color=c, label=f"{name}: work (1/inflation)")
        ax.plot(k, [r["wall_efficiency"] for r in rows], "s--", color=c, alpha=0.7, label=f"{name}: wall")
    ax.axhline(1.0, color="0.5", lw=0.8, ls=":")
    if len(all_ranks) > 2 and all_ranks[-1] / all_ranks[0] >= 4:
        ax.set_xscale("log", base=2)
    ax.set_xticks(all_ranks)
    ax.set_xticklabels([str(k) for k in all_ranks])
    ax.set_xlabel("MPI ranks")
    ax.set_ylabel("parallel efficiency")
    ax.set_ylim(bottom=0.0)
    ax.set_title("pmpm bench scaling")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("files", nargs="+", help="JSON-lines result files of pmpm bench scaling")
    p.add_argument("-o", "--outdir", default=".", help="where to write the table and plot (default: .)")
    p.add_argument("--name", default="scaling", help="file name prefix (default: scaling)")
    args = p.parse_args(argv)
    for f in args.files:
        if not os.path.isfile(f):
            print(f"gather_scaling: error: {f}: no such file", file=sys.stderr)
            return 2
    try:
        results = read_results(args.files)
    except ValueError as exc:
        print(f"gather_scaling: error: {exc}", file=sys.stderr)
        return 2
    if not results:
        print(f"gather_scaling: error: no results in {', '.join(args.files)}", file=sys.stderr)
        return 2
    table = build_table(results)
    os.makedirs(args.outdir, exist_ok=True)
    csv_path = os.path.join(args.outdir, f"{args.name}.csv")
    md_path = os.path.join(args.outdir, f"{args.name}.md")
    png_path = os.path.join(args.outdir, f"{args.name}_efficiency.png")
    write_csv(table, csv_path)
    md = markdown(table)
    with open(md_path, "w", encoding="utf-8") as fh:
        fh.write(md)
    plot(table, png_path)
    print(md, end="")
    for path in (csv_path, md_path, png_path):
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
