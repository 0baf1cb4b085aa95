"""A model of the distributed step time, fitted to ``pmpm bench scaling`` measurements.

    T(P) = n t_c + M (alpha + b / (M beta)) + ceil(log2 P) alpha_r

per step and rank, for n particles per rank: t_c is the compute time per particle-step (from
the 1-rank run), M and b the messages and bytes a rank sends per step (measured: they depend on
the slab boundary, not on n), alpha and beta the network latency and bandwidth, alpha_r the
latency of one stage of the allreduce of the time step (one per step, plus a few more for the
energy check every 10 steps). Weak scaling keeps n fixed, so its efficiency is T(1) / T(P).

    python -m studies.scaling_model results.jsonl [--latency 2e-6] [--bandwidth 1e10]

reads JSON lines of ``pmpm bench scaling --mode weak`` and prints the fit and a projection to
1024 ranks as Markdown.
"""
import argparse
import json
import math

__all__ = ["fit", "project", "main"]

#: messages a rank sends per MUSL step with two neighbours: two halo exchanges (after P2G and
#: after the re-map), each an accumulate and a fill to each neighbour, plus the migration's
#: count and data messages to each neighbour
MESSAGES_PER_STEP = 2 * 2 * 2 + 2 * 2


def fit(rows):
    """Compute time per particle-step and bytes per step per rank from measured rows."""
    one = min(rows, key=lambda r: r["ranks"])
    t_c = one["one_rank_cpu_s"] / (one["particles"] * one["steps"])
    multi = [r for r in rows if r["ranks"] > 1] or [one]
    bytes_step = max(r["halo_bytes_per_step"] + r["migration_bytes_per_step"] for r in multi)
    return {"t_c": t_c, "bytes_per_step": bytes_step,
            "particles_per_rank": one["particles"] / one["ranks"]}


def project(model, latency, bandwidth, reduce_latency, ranks):
    """Rows (P, step time s, efficiency) of weak scaling with the fitted model."""
    n = model["particles_per_rank"]
    t1 = n * model["t_c"]
    out = []
    for p in ranks:
        comm = 0.0 if p == 1 else MESSAGES_PER_STEP * latency + model["bytes_per_step"] / bandwidth
        reduce = math.ceil(math.log2(p)) * reduce_latency * 1.2 if p > 1 else 0.0
        t = t1 + comm + reduce
        out.append((p, t, t1 / t))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", help="JSON lines from pmpm bench scaling --mode weak")
    ap.add_argument("--latency", type=float, default=2e-6, help="point-to-point latency, s")
    ap.add_argument("--bandwidth", type=float, default=1e10, help="link bandwidth, bytes/s")
    ap.add_argument("--reduce-latency", type=float, default=3e-6, help="allreduce stage latency, s")
    args = ap.parse_args(argv)
    rows = []
    for line in open(args.results):
        line = line.strip()
        if line.startswith("{"):
            rows.append(json.loads(line))
    model = fit(rows)
    print(f"fitted: {model['t_c'] * 1e9:.1f} ns per particle-step, {model['bytes_per_step']:.0f} bytes "
          f"and {MESSAGES_PER_STEP} messages per step per rank, {model['particles_per_rank']:.0f} particles per rank")
    print(f"network: latency {args.latency * 1e6:g} us, bandwidth {args.bandwidth / 1e9:g} GB/s, "
          f"allreduce stage {args.reduce_latency * 1e6:g} us\n")
    print("| ranks | step time (ms) | weak-scaling efficiency |")
    print("| ---: | ---: | ---: |")
    for p, t, eff in project(model, args.latency, args.bandwidth, args.reduce_latency,
                             [1, 2, 4, 16, 64, 256, 1024]):
        print(f"| {p} | {t * 1e3:.3f} | {eff:.4f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
