#!/usr/bin/env python3
"""Turns results/replan_tasks.csv (bench_replan_suite) into results/replan_table1.png: success rate
and mean smoothness (jerk integral, on the tasks every method solved) per density and method."""
import csv
import sys
from collections import defaultdict

import matplotlib
matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402


def main(argv):
    src = argv[1] if len(argv) > 1 else 'results/replan_tasks.csv'
    dst = argv[2] if len(argv) > 2 else 'results/replan_table1.png'
    rows = list(csv.DictReader(open(src)))
    methods = ['proposed', 'gto', 'gto_restart', 'astar_pgo']
    densities = ['low', 'medium', 'high']
    ok = defaultdict(list)
    solved_by = defaultdict(int)
    for r in rows:
        ok[(r['density'], r['method'])].append(r['ok'] == '1')
        if r['ok'] == '1':
            solved_by[(r['density'], r['trial'])] += 1
    jerk = defaultdict(list)
    for r in rows:
        if r['ok'] == '1' and solved_by[(r['density'], r['trial'])] == len(methods):
            jerk[(r['density'], r['method'])].append(float(r['jerk_integral']))
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    width = 0.2
    for i, m in enumerate(methods):
        xs = [d + (i - 1.5) * width for d in range(len(densities))]
        rate = [100.0 * sum(ok[(d, m)]) / max(1, len(ok[(d, m)])) for d in densities]
        smooth = [sum(jerk[(d, m)]) / max(1, len(jerk[(d, m)])) for d in densities]
        axes[0].bar(xs, rate, width, label=m)
        axes[1].bar(xs, smooth, width, label=m)
    for ax, title, unit in ((axes[0], 'Success rate', '%'), (axes[1], 'Smoothness (tasks all solved)', 'm^2/s^5')):
        ax.set_xticks(range(len(densities)))
        ax.set_xticklabels(densities)
        ax.set_title(title)
        ax.set_ylabel(unit)
        ax.grid(axis='y', alpha=0.3)
    axes[0].set_ylim(0, 105)
    axes[0].legend(loc='lower left')
    fig.suptitle('Replanning benchmark (Table I): %d tasks per density' % (len(ok[('medium', 'proposed')])))
    fig.tight_layout()
    fig.savefig(dst, dpi=110)
    print('wrote ' + dst)
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv))
