#!/usr/bin/env python3
"""Both learning curves of benches/sac_vs_ppo.sh in one figure: training success rate against env
steps (left) and against wall time (right), one line per run directory given.

    python3 benches/plot_sac_vs_ppo.py OUT.png RUN_DIR [RUN_DIR ...]     (needs matplotlib)

Each run's label is its directory name; the success rate is the fraction of the episodes that
ended in each iteration that succeeded, smoothed over 5 iterations (episode-weighted)."""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def curve(run):
    rows = list(csv.DictReader(open(f"{run}/metrics.csv")))
    steps, secs, rate = [], [], []
    for i in range(len(rows)):
        window = rows[max(0, i - 4):i + 1]
        n = sum(float(r["episode/count"]) for r in window)
        ok = sum(float(r["episode/count"]) * float(r["episode/success_rate"]) for r in window if float(r["episode/count"]) > 0)
        steps.append(float(rows[i]["env_steps"]) / 1e6)
        secs.append(float(rows[i]["time_s"]))
        rate.append(100.0 * ok / n if n > 0 else 0.0)
    return steps, secs, rate


def main():
    if len(sys.argv) < 3:
        sys.exit("usage: plot_sac_vs_ppo.py OUT.png RUN_DIR [RUN_DIR ...]")
    out, runs = sys.argv[1], sys.argv[2:]
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4), dpi=100)
    for run in runs:
        steps, secs, rate = curve(run)
        label = run.rstrip("/").split("/")[-1]
        a.plot(steps, rate, label=label)
        b.plot(secs, rate, label=label)
    for ax, xlabel in [(a, "env steps (millions)"), (b, "wall time (s)")]:
        ax.axhline(90, color="grey", linestyle=":", linewidth=1)
        ax.set_xlabel(xlabel)
        ax.set_ylabel("training success (%), 5-iteration mean")
        ax.grid(alpha=0.3)
        ax.legend()
    fig.tight_layout()
    fig.savefig(out)


if __name__ == "__main__":
    main()
