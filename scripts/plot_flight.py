#!/usr/bin/python3
"""Top view of a simulated flight from the flight monitor's files (DIR/NAME*.csv, NAME_report.json):
the obstacle columns of the true map (grey squares, darker = taller), the planner's reference
trajectories (thin dashed), the flown path coloured by speed, the replanning points (failures in
red), the goals (stars) and the start. Writes DIR/NAME.png.

  plot_flight.py DIR NAME [--out PNG] [--print-report]

--print-report prints the flight report (from the JSON) and exits non-zero unless the flight
succeeded; run_flight.sh uses it.
"""
import argparse
import csv
import json
import math
import os
import sys

import matplotlib
matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402


def read_csv(path):
    if not os.path.exists(path):
        return []
    with open(path, newline='') as f:
        return list(csv.DictReader(f))


def num(x):
    """float of a CSV/JSON value; NaN for empty, 'nan' or None."""
    try:
        return float(x)
    except (TypeError, ValueError):
        return math.nan


def fmt(x, digits=2):
    x = num(x)
    return 'n/a' if math.isnan(x) else f'{x:.{digits}f}'


def report_text(r):
    """The flight report, as the monitor prints it."""
    scenario = r.get('scenario') or {}
    sc = ', '.join(f'{k} {v}' for k, v in sorted(scenario.items()))
    lines = [
        f"flight report ({r.get('name', '')}): {'SUCCESS' if r.get('success') else 'FAILURE'} "
        f"({r.get('status')}: {r.get('message')})",
    ]
    if sc:
        lines.append(f'  scenario             {sc}')
    for g in r.get('goals', []):
        state = 'reached' if g.get('reached') else ('timed out' if g.get('timed_out') else
                                                    ('not reached' if g.get('sent') else 'not sent'))
        gm = g.get('goal_m') or [math.nan] * 3
        lines.append(f"  goal {g['index'] + 1} ({fmt(gm[0], 1)}, {fmt(gm[1], 1)}, {fmt(gm[2], 1)})  {state:11s}"
                     f" time {fmt(g.get('time_s'), 1)} s, path {fmt(g.get('path_length_m'), 1)} m,"
                     f" {g.get('replans', 0)} replans ({g.get('replan_failures', 0)} failed),"
                     f" min clearance {fmt(g.get('min_clearance_m'))} m, collisions {g.get('collisions', 0)}")
    lines += [
        f"  goals reached        {r.get('goals_reached')}/{r.get('goals_total')}",
        f"  collisions           {r.get('collisions')} (simulator {r.get('sim_collisions')}, "
        f"clearance check {r.get('clearance_contacts')})",
        f"  min clearance        {fmt(r.get('min_clearance_m'))} m",
        f"  speed mean / max     {fmt(r.get('mean_speed_mps'))} / {fmt(r.get('max_speed_mps'))} m/s",
        f"  replans              {r.get('replans')} ({r.get('replan_failures')} failed)",
        f"  replanning time      median {fmt(r.get('replan_ms_median'), 1)} ms, p95 {fmt(r.get('replan_ms_p95'), 1)} ms,"
        f" max {fmt(r.get('replan_ms_max'), 1)} ms",
        f"  duration             {fmt(r.get('duration_s'), 1)} s, path {fmt(r.get('path_length_m'), 1)} m",
    ]
    return '\n'.join(lines)


def plot(directory, name, out):
    stem = os.path.join(directory, name)
    with open(stem + '_report.json') as f:
        report = json.load(f)
    trace = read_csv(stem + '.csv')
    events = read_csv(stem + '_events.csv')
    columns = read_csv(stem + '_map.csv')
    references = read_csv(stem + '_reference.csv')
    res = num(report.get('map_resolution_m')) or 0.1

    fig, ax = plt.subplots(figsize=(13, 8.5))
    xs, ys = [], []

    # Obstacle columns: one grey square per occupied x-y voxel column, shaded by its height.
    if columns:
        cx = np.array([num(c['x']) for c in columns])
        cy = np.array([num(c['y']) for c in columns])
        cz = np.array([num(c['z_max']) for c in columns])
        ix = np.rint((cx - cx.min()) / res).astype(int)
        iy = np.rint((cy - cy.min()) / res).astype(int)
        grid = np.full((iy.max() + 1, ix.max() + 1), np.nan)
        grid[iy, ix] = cz
        extent = (cx.min() - res / 2, cx.max() + res / 2, cy.min() - res / 2, cy.max() + res / 2)
        ax.imshow(np.ma.masked_invalid(grid), origin='lower', extent=extent, cmap='Greys',
                  vmin=-0.5 * np.nanmax(cz), vmax=1.4 * np.nanmax(cz), interpolation='nearest', zorder=1)
        xs += [extent[0], extent[1]]
        ys += [extent[2], extent[3]]

    # References: each new one thin and dashed.
    by_id = {}
    for r in references:
        by_id.setdefault(r['id'], []).append((num(r['x']), num(r['y'])))
    for k, (rid, pts) in enumerate(sorted(by_id.items(), key=lambda kv: int(kv[0]))):
        p = np.array(pts)
        ax.plot(p[:, 0], p[:, 1], '--', color='tab:blue', lw=0.8, alpha=0.6, zorder=2,
                label='reference' if k == 0 else None)

    # The flown path, coloured by speed.
    if len(trace) >= 2:
        p = np.array([[num(r['x']), num(r['y'])] for r in trace])
        speed = np.array([num(r['speed']) for r in trace])
        seg = np.stack([p[:-1], p[1:]], axis=1)
        lc = LineCollection(seg, cmap='plasma', linewidths=2.2, zorder=4)
        lc.set_array(0.5 * (speed[:-1] + speed[1:]))
        lc.set_clim(0.0, max(0.5, float(np.nanmax(speed))))
        ax.add_collection(lc)
        fig.colorbar(lc, ax=ax, fraction=0.035, pad=0.02, label='speed [m/s]')
        xs += list(p[:, 0])
        ys += list(p[:, 1])

    # Contacts: samples closer to the true map than the body radius.
    radius = num(report.get('collision_radius_m'))
    if math.isnan(radius):
        radius = 0.15
    hits = [(num(r['x']), num(r['y'])) for r in trace if num(r['clearance_m']) < radius]
    if hits:
        p = np.array(hits)
        ax.scatter(p[:, 0], p[:, 1], s=16, color='red', zorder=7, label=f'contact (clearance < {radius:.2f} m)')

    # Replanning points: where each planned trajectory starts; failed calls in red, emergency stops
    # (a braking trajectory) in orange.
    def published(e):
        return int(num(e.get('trajectory_id', 0))) >= 0
    ok = [(num(e['x']), num(e['y'])) for e in events if published(e) and e.get('trigger') != 'emergency']
    bad = [(num(e['x']), num(e['y'])) for e in events if not published(e)]
    stops = [(num(e['x']), num(e['y'])) for e in events if e.get('trigger') == 'emergency']
    if stops:
        p = np.array(stops)
        ax.scatter(p[:, 0], p[:, 1], s=60, marker='v', color='darkorange', edgecolors='black', linewidths=0.6,
                   zorder=6, label=f'emergency stop ({len(stops)})')
    if ok:
        p = np.array(ok)
        ax.scatter(p[:, 0], p[:, 1], s=14, facecolors='white', edgecolors='black', linewidths=0.6, zorder=5,
                   label=f'replan ({len(ok)})')
    if bad:
        p = np.array(bad)
        ax.scatter(p[:, 0], p[:, 1], s=40, marker='x', color='red', linewidths=1.5, zorder=6,
                   label=f'failed plan ({len(bad)})')

    # Minimum clearance, start and goals.
    mc = report.get('min_clearance_position_m')
    if mc and report.get('min_clearance_m') is not None:
        ax.scatter([mc[0]], [mc[1]], s=70, marker='D', facecolors='none', edgecolors='magenta', linewidths=1.5,
                   zorder=7, label=f"min clearance {fmt(report.get('min_clearance_m'))} m")
    start = report.get('start_m')
    if start and start[0] is not None:
        ax.scatter([start[0]], [start[1]], s=120, marker='^', color='limegreen', edgecolors='black', zorder=8,
                   label='start')
        xs.append(start[0])
        ys.append(start[1])
    for k, g in enumerate(report.get('goals', [])):
        gx, gy = g['goal_m'][0], g['goal_m'][1]
        ax.scatter([gx], [gy], s=260, marker='*', color='gold' if g.get('reached') else 'white',
                   edgecolors='black' if g.get('reached') else 'red', linewidths=1.0, zorder=8,
                   label='goal (reached)' if k == 0 else None)
        ax.annotate(str(g['index'] + 1), (gx, gy), xytext=(7, 7), textcoords='offset points', fontsize=11,
                    fontweight='bold', zorder=9)
        xs.append(gx)
        ys.append(gy)

    if xs:
        ax.set_xlim(min(xs) - 1.0, max(xs) + 1.0)
        ax.set_ylim(min(ys) - 1.0, max(ys) + 1.0)
    ax.set_aspect('equal')
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    ax.grid(True, lw=0.3, alpha=0.5)
    sc = report.get('scenario') or {}
    scen = ', '.join(f'{k} {v}' for k, v in sorted(sc.items()))
    ax.set_title(
        f"{report.get('name', name)}{' (' + scen + ')' if scen else ''}: "
        f"{'SUCCESS' if report.get('success') else 'FAILURE'}, "
        f"{report.get('goals_reached')}/{report.get('goals_total')} goals, {report.get('collisions')} "
        f"collision{'' if report.get('collisions') == 1 else 's'}, "
        f"min clearance {fmt(report.get('min_clearance_m'))} m\n"
        f"speed mean {fmt(report.get('mean_speed_mps'))} / max {fmt(report.get('max_speed_mps'))} m/s, "
        f"{report.get('replans')} replans ({report.get('replan_failures')} failed), replanning median "
        f"{fmt(report.get('replan_ms_median'), 1)} ms / p95 {fmt(report.get('replan_ms_p95'), 1)} ms, "
        f"{fmt(report.get('duration_s'), 1)} s, {fmt(report.get('path_length_m'), 1)} m", fontsize=10)
    ax.legend(loc='upper left', fontsize=8, framealpha=0.85)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return report


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('dir')
    ap.add_argument('name')
    ap.add_argument('--out', help='PNG path (default DIR/NAME.png)')
    ap.add_argument('--print-report', action='store_true', help='print the report; exit 1 unless it succeeded')
    ap.add_argument('--no-plot', action='store_true')
    a = ap.parse_args(argv[1:])
    path = os.path.join(a.dir, a.name + '_report.json')
    if not os.path.exists(path):
        print(f'plot_flight: no report {path} (the flight monitor did not finish)', file=sys.stderr)
        return 2
    with open(path) as f:
        report = json.load(f)
    if not a.no_plot:
        out = a.out or os.path.join(a.dir, a.name + '.png')
        plot(a.dir, a.name, out)
        print(f'plot_flight: wrote {out}')
    if a.print_report:
        print(report_text(report))
        return 0 if report.get('success') else 1
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv))
