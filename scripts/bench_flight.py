#!/usr/bin/python3
"""Closed-loop flight benchmark (make bench-flight): kinds of world and sensing, flown one after the
other, headless, with the flight monitor; aggregates the reports.

--suite worlds (the default): for each world style (forest at medium and high density; windows:
full-width walls pierced by 1-3 windows; rings; boxes: floating 3-D boxes; mixed: short walls,
rings and a window wall, all at medium density), each sensing profile (ideal; realistic: VIO noise,
drift and latency seen by the mapping too, depth noise growing with range squared, invalid pixels;
simulator.launch sensing:=) and seeds 1..N: path_searching's flight_world writes the world as an
OctoMap and draws three goals, each either in the open (at the two ends, x = +-15) or beside
obstacles (0.5-0.8 m from the nearest one, inside the area), verified reachable with the global
route on the true map. The planner's window is the area's width in y (the walls close it). Files go
to OUT/bench_flight/<style>-<density>_<sensing>_s<seed>*. Ends with
  RESULT flights=... goals_reached_rate=... collisions=... failed_replan_rate=... mean_speed_mps=...
         rate_<style>=... rate_<sensing>=... near_goals_rate=...

--suite forests: the earlier benchmark, kept for comparison: seeded forests at medium and high
density, goals in the open at the two ends of the forest, ideal sensing.

Each flight: scripts/run_flight.sh with --density D --seed S --max-vel V and several goals: seeded
random goals alternating between the two ends of the forest (x = +15 and x = -15, y in [-8, 8],
z in [0.8, 1.6]; the vehicle starts at (-15, 0, 1)), or the scenario's three default goals with
--default-goals. Files go to OUT/bench_flight/<density>_s<seed>*.

Writes OUT/bench_flight.md (a table per density and overall, and one row per flight) and ends with
  RESULT flights=20 goals_reached_rate=... collisions=... min_clearance_m=... mean_speed_mps=...
         replan_ms_median=... replan_ms_p95=...
(one line). Replanning times are pooled over every planning call of every flight of the group.
"""
import argparse
import csv
import json
import math
import os
import random
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def percentile(values, q):
    """Nearest rank, as plan_env/timing.h; 0 for no values."""
    if not values:
        return 0.0
    v = sorted(values)
    return v[min(len(v) - 1, int(q * (len(v) - 1) + 0.5))]


def num(x):
    try:
        return float(x)
    except (TypeError, ValueError):
        return math.nan


def random_goals(density, seed, n):
    """n goals alternating between the far end (x = +15) and the start end (x = -15) of the forest."""
    rng = random.Random(f'{density}-{seed}')
    goals = []
    for k in range(n):
        x = 15.0 if k % 2 == 0 else -15.0
        goals += [x, round(rng.uniform(-8.0, 8.0), 2), round(rng.uniform(0.8, 1.6), 2)]
    return goals


def run_flight(args, density, seed, out_dir, name=None, goals=None, extra=(), style='forest'):
    name = name or f'{density}_s{seed}'
    cmd = ['bash', os.path.join(ROOT, 'scripts', 'run_flight.sh'), '--density', density, '--seed', str(seed),
           '--map-style', style, '--max-vel', str(args.max_vel), '--goal-timeout', str(args.goal_timeout),
           '--output-dir', out_dir, '--name', name, '--rviz', 'false']
    if goals is not None:
        cmd += ['--goals', ' '.join(goals)]
    elif not args.default_goals:
        cmd += ['--goals', ' '.join(str(g) for g in random_goals(density, seed, args.goals))]
    if args.no_plot:
        cmd.append('--no-plot')
    if args.sim_time:
        cmd += ['--sim-time', 'true']
    cmd += list(extra)
    t0 = time.time()
    log_path = os.path.join(out_dir, name + '.log')
    with open(log_path, 'w') as log:
        rc = subprocess.call(cmd, stdout=log, stderr=subprocess.STDOUT)
    wall = time.time() - t0
    report_path = os.path.join(out_dir, name + '_report.json')
    report = None
    if os.path.exists(report_path):
        with open(report_path) as f:
            report = json.load(f)
    ms = []
    events_path = os.path.join(out_dir, name + '_events.csv')
    if os.path.exists(events_path):
        with open(events_path, newline='') as f:
            ms = [num(r['total_ms']) for r in csv.DictReader(f) if r.get('fallback') != 'reroute']
        ms = [m for m in ms if not math.isnan(m)]
    return {'name': name, 'density': density, 'seed': seed, 'rc': rc, 'wall_s': wall, 'report': report,
            'replan_ms': ms, 'goals_total': report['goals_total'] if report else args.goals, 'log': log_path}


def run_world_flight(args, style, density, sensing, seed, out_dir):
    """One flight of the worlds suite: flight_world makes the map and the goals, run_flight flies them."""
    name = f'{style}-{density}_{sensing}_s{seed}'  # the density too: forest-medium and forest-high differ only there
    bt = os.path.join(out_dir, name + '.bt')
    tool = os.path.join(args.ws, 'devel', 'lib', 'topo_planner', 'flight_world')
    world = subprocess.run([tool, '--style', style, '--density', density, '--seed', str(seed), '--goals', str(args.goals),
                            '--out', bt], capture_output=True, text=True)
    lines = dict(l.split(' ', 1) for l in world.stdout.splitlines() if ' ' in l)
    if world.returncode != 0 or 'GOALS' not in lines:
        print(f'bench_flight: flight_world failed for {name}: {world.stderr.strip()}', flush=True)
        return {'name': name, 'style': style, 'sensing': sensing, 'seed': seed, 'rc': world.returncode, 'wall_s': 0.0,
                'report': None, 'replan_ms': [], 'goals_total': args.goals, 'kinds': [], 'log': bt}
    goals = lines['GOALS'].split()
    kinds = lines.get('KINDS', '').split()
    report_path = os.path.join(out_dir, name + '_report.json')
    if args.resume and os.path.exists(report_path):  # flown by an earlier run: its files are reused
        with open(report_path) as fh:
            report = json.load(fh)
        events_path = os.path.join(out_dir, name + '_events.csv')
        ms = []
        if os.path.exists(events_path):
            with open(events_path, newline='') as fh:
                ms = [m for m in (num(r['total_ms']) for r in csv.DictReader(fh) if r.get('fallback') != 'reroute')
                      if not math.isnan(m)]
        return {'name': name, 'style': style, 'sensing': sensing, 'seed': seed, 'rc': 0, 'wall_s': 0.0, 'report': report,
                'replan_ms': ms, 'goals_total': report['goals_total'], 'kinds': kinds,
                'log': os.path.join(out_dir, name + '.log')}
    extra = ['--', f'map_file:={bt}', f'sensing:={sensing}', 'map_origin:=[-20.0, -10.0, 0.3]',
             'map_size:=[40.0, 20.0, 3.4]']
    if args.dump_failed_plans:
        extra.append(f'dump_failed_plans:={os.path.join(out_dir, name + "_plans")}')
    # The map comes from the file: the generator's style does not apply (and 'boxes' is not one of its).
    f = run_flight(args, density, seed, out_dir, name=name, goals=goals, extra=extra)
    f.update({'style': style, 'sensing': sensing, 'kinds': kinds})
    return f


def aggregate(flights):
    goals_total = sum(f['goals_total'] for f in flights)
    reached = sum(f['report']['goals_reached'] for f in flights if f['report'])
    collisions = sum(f['report']['collisions'] for f in flights if f['report'])
    clear = [num(f['report']['min_clearance_m']) for f in flights if f['report']]
    clear = [c for c in clear if not math.isnan(c)]
    speeds = [num(f['report']['mean_speed_mps']) for f in flights if f['report']]
    max_speeds = [num(f['report']['max_speed_mps']) for f in flights if f['report']]
    ms = [m for f in flights for m in f['replan_ms']]
    return {
        'flights': len(flights),
        'success': sum(1 for f in flights if f['report'] and f['report']['success']),
        'no_report': sum(1 for f in flights if not f['report']),
        'goals_total': goals_total,
        'goals_reached': reached,
        'goals_reached_rate': reached / goals_total if goals_total else 0.0,
        'collisions': collisions,
        'min_clearance_m': min(clear) if clear else math.nan,
        'mean_speed_mps': sum(speeds) / len(speeds) if speeds else math.nan,
        'max_speed_mps': max(max_speeds) if max_speeds else math.nan,
        'replans': sum(f['report']['replans'] for f in flights if f['report']),
        'replan_failures': sum(f['report']['replan_failures'] for f in flights if f['report']),
        # The FSM's stall re-routes (no progress for fsm/progress_timeout_s): not planning calls.
        'stalls': sum(f['report'].get('stalls', 0) for f in flights if f['report']),
        'near_goals': sum(k == 'near' for f in flights for k in f.get('kinds', [])),
        'near_reached': sum(1 for f in flights if f['report'] for g, k in zip(f['report'].get('goals', []), f.get('kinds', []))
                            if k == 'near' and g.get('reached')),
        'replan_ms_median': percentile(ms, 0.5),
        'replan_ms_p95': percentile(ms, 0.95),
        'duration_s': sum(num(f['report']['duration_s']) for f in flights if f['report']) / max(
            1, sum(1 for f in flights if f['report'])),
    }


def fmt(x, d=2):
    return 'n/a' if x is None or (isinstance(x, float) and math.isnan(x)) else f'{x:.{d}f}'


def summary_table(groups):
    lines = ['| group | flights | success | goals reached | rate | collisions | min clearance [m] | '
             'mean speed [m/s] | max speed [m/s] | published (failed) replans | replan median [ms] | replan p95 [ms] | '
             'mean duration [s] |',
             '|---|---|---|---|---|---|---|---|---|---|---|---|---|']
    for label, a in groups:
        lines.append(f"| {label} | {a['flights']} | {a['success']} | {a['goals_reached']}/{a['goals_total']} | "
                     f"{fmt(a['goals_reached_rate'], 3)} | {a['collisions']} | {fmt(a['min_clearance_m'])} | "
                     f"{fmt(a['mean_speed_mps'])} | {fmt(a['max_speed_mps'])} | {a['replans']} ({a['replan_failures']}) | "
                     f"{fmt(a['replan_ms_median'], 1)} | {fmt(a['replan_ms_p95'], 1)} | {fmt(a['duration_s'], 1)} |")
    return lines


def flight_table(flights):
    lines = ['| flight | result | goals | collisions | min clearance [m] | mean / max speed [m/s] | published (failed) replans | '
             'replan median / p95 [ms] | duration [s] | wall [s] |',
             '|---|---|---|---|---|---|---|---|---|---|']
    for f in flights:
        r = f['report']
        if not r:
            lines.append(f"| {f['name']} | no report (exit {f['rc']}, see {os.path.basename(f['log'])}) | | | | | | | | "
                         f"{fmt(f['wall_s'], 0)} |")
            continue
        lines.append(f"| {f['name']} | {'ok' if r['success'] else r['status']} | {r['goals_reached']}/{r['goals_total']} | "
                     f"{r['collisions']} | {fmt(num(r['min_clearance_m']))} | {fmt(num(r['mean_speed_mps']))} / "
                     f"{fmt(num(r['max_speed_mps']))} | {r['replans']} ({r['replan_failures']}) | "
                     f"{fmt(num(r['replan_ms_median']), 1)} / {fmt(num(r['replan_ms_p95']), 1)} | "
                     f"{fmt(num(r['duration_s']), 1)} | {fmt(f['wall_s'], 0)} |")
    return lines


def write_report(args, md, summary, result):
    """OUT/bench_flight.md (the tables and the RESULT line), and the summary and RESULT on stdout."""
    md = md + ['', '```', result, '```', '']
    md_path = os.path.join(args.out, 'bench_flight.md')
    with open(md_path, 'w') as f:
        f.write('\n'.join(md))
    print()
    print('\n'.join(summary))
    print(f'bench_flight: wrote {md_path}')
    print(result)
    return 0


def failed_rate(a):
    # Of all planning calls: 'replans' counts the calls that published, 'replan_failures' the others.
    calls = a['replans'] + a['replan_failures']
    return a['replan_failures'] / calls if calls else 0.0


def worlds_suite(args):
    if args.seeds == 10:
        args.seeds = 3  # the worlds suite's default: 6 styles x 2 sensing profiles x 3 seeds = 36 flights
    out_dir = os.path.join(args.out, 'bench_flight')
    os.makedirs(out_dir, exist_ok=True)
    styles = [s.split('-') if '-' in s else [s, 'medium'] for s in args.styles.split(',') if s]
    sensings = [s for s in args.sensing.split(',') if s]
    cases = [(st, de, se, seed) for st, de in styles for se in sensings for seed in range(1, args.seeds + 1)]
    print(f'bench_flight: {len(cases)} flights (styles {args.styles}; sensing {args.sensing}; seeds 1..{args.seeds}), '
          f'max_vel {args.max_vel} m/s, {args.goals} goals each; files in {out_dir}', flush=True)
    flights = []
    for st, de, se, seed in cases:
        f = run_world_flight(args, st, de, se, seed, out_dir)
        f['group'] = f'{st}-{de}' if st == 'forest' else st
        flights.append(f)
        r = f['report']
        label = f"{f['group']}/{se}/s{seed}"
        if r:
            print(f"[{len(flights):2d}/{len(cases)}] {label:28s} {'ok  ' if r['success'] else 'FAIL'} "
                  f"goals {r['goals_reached']}/{r['goals_total']} ({' '.join(f['kinds'])}) collisions {r['collisions']} "
                  f"min clearance {fmt(num(r['min_clearance_m']))} m speed {fmt(num(r['mean_speed_mps']))} m/s "
                  f"replans {r['replans']} ({r['replan_failures']} failed) p95 {fmt(num(r['replan_ms_p95']), 1)} ms "
                  f"(wall {f['wall_s']:.0f} s){'' if r['success'] else ': ' + r['message']}", flush=True)
        else:
            print(f"[{len(flights):2d}/{len(cases)}] {label:28s} NO REPORT (exit {f['rc']}, see {f['log']})", flush=True)

    groups = []
    group_names = list(dict.fromkeys(f['group'] for f in flights))
    for g in group_names:
        for se in sensings:
            groups.append((f'{g} / {se}', aggregate([f for f in flights if f['group'] == g and f['sensing'] == se])))
    per_style = [(g, aggregate([f for f in flights if f['group'] == g])) for g in group_names]
    per_sensing = [(se, aggregate([f for f in flights if f['sensing'] == se])) for se in sensings]
    overall = aggregate(flights)
    def table(rows):
        lines = ['| group | flights | goals reached | rate | near goals reached | collisions | failed replans | '
                 'stalls | min clearance [m] | mean speed [m/s] | replan median / p95 [ms] |',
                 '|---|---|---|---|---|---|---|---|---|---|---|']
        for label, a in rows:
            lines.append(f"| {label} | {a['flights']} | {a['goals_reached']}/{a['goals_total']} | {fmt(a['goals_reached_rate'], 3)} | "
                         f"{a['near_reached']}/{a['near_goals']} | {a['collisions']} | {a['replan_failures']}/{a['replans'] + a['replan_failures']} "
                         f"({100 * failed_rate(a):.1f}%) | {a['stalls']} | {fmt(a['min_clearance_m'])} | {fmt(a['mean_speed_mps'])} | "
                         f"{fmt(a['replan_ms_median'], 1)} / {fmt(a['replan_ms_p95'], 1)} |")
        return lines
    md = ['# Closed-loop flight benchmark: kinds of world and sensing', '',
          f'{len(flights)} flights: styles {args.styles}, sensing {args.sensing}, seeds 1..{args.seeds}, max_vel '
          f'{args.max_vel} m/s, {args.goals} goals each (in the open or 0.5-0.8 m beside obstacles, verified reachable '
          f'with the global route on the true map), goal timeout {args.goal_timeout:.0f} s. Failed replans: planning '
          'calls that published nothing, over all calls. Stalls: the FSM found no progress towards the goal for '
          'fsm/progress_timeout_s and re-routed (not a planning call).', '', '## Per style and sensing', '']
    md += table(groups)
    md += ['', '## Per style', ''] + table(per_style)
    md += ['', '## Per sensing', ''] + table(per_sensing + [('overall', overall)])
    md += ['', '## Flights', ''] + flight_table(flights)
    rates = ' '.join(f"rate_{g.replace('-', '_')}={a['goals_reached_rate']:.3f}" for g, a in per_style)
    rates += ' ' + ' '.join(f"rate_{se}={a['goals_reached_rate']:.3f}" for se, a in per_sensing)
    near = overall['near_reached'] / overall['near_goals'] if overall['near_goals'] else 0.0
    result = (f"RESULT flights={overall['flights']} goals_reached_rate={overall['goals_reached_rate']:.3f} "
              f"collisions={overall['collisions']} failed_replan_rate={failed_rate(overall):.3f} stalls={overall['stalls']} "
              f"mean_speed_mps={fmt(overall['mean_speed_mps'], 2)} near_goals_rate={near:.3f} {rates} "
              f"replan_ms_median={overall['replan_ms_median']:.2f} replan_ms_p95={overall['replan_ms_p95']:.2f}")
    return write_report(args, md, table(per_style + per_sensing + [('overall', overall)]), result)


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--out', default=os.path.join(ROOT, 'results'), help='results directory')
    ap.add_argument('--densities', default='medium,high')
    ap.add_argument('--seeds', type=int, default=10, help='seeds 1..N per density')
    ap.add_argument('--max-vel', type=float, default=3.0)
    ap.add_argument('--goals', type=int, default=3, help='random goals per flight')
    ap.add_argument('--default-goals', action='store_true', help="the scenario's three default goals instead")
    ap.add_argument('--goal-timeout', type=float, default=90.0)
    ap.add_argument('--sim-time', action='store_true',
                    help='run the simulations on simulated time (TOPO_PLANNER_TIME_LIMIT_SCALE stretches '
                         'the lockstep waits on a loaded machine)')
    ap.add_argument('--no-plot', action='store_true', help='no PNG per flight')
    ap.add_argument('--suite', default='worlds', choices=['worlds', 'forests'])
    ap.add_argument('--styles', default='forest-medium,forest-high,windows,rings,boxes,mixed',
                    help='worlds suite: style[-density] list (density medium unless given)')
    ap.add_argument('--sensing', default='ideal,realistic', help='worlds suite: sensing profiles')
    ap.add_argument('--resume', action='store_true',
                    help='worlds suite: reuse the reports of flights already in OUT (an interrupted run)')
    ap.add_argument('--dump-failed-plans', action='store_true',
                    help='worlds suite: save each failed replanning problem in OUT/bench_flight/<flight>_plans for '
                         'replay_plan.launch (planner.launch dump_failed_plans)')
    args = ap.parse_args(argv[1:])
    args.ws = os.environ.get('WS', os.path.join(ROOT, 'build', 'ws'))
    if args.default_goals:
        args.goals = 3
    if args.suite == 'worlds':
        return worlds_suite(args)

    out_dir = os.path.join(args.out, 'bench_flight')
    os.makedirs(out_dir, exist_ok=True)
    densities = [d for d in args.densities.split(',') if d]
    flights = []
    total = len(densities) * args.seeds
    print(f'bench_flight: {total} flights ({", ".join(densities)} x seeds 1..{args.seeds}), max_vel {args.max_vel} m/s, '
          f'{args.goals} goals each; files in {out_dir}', flush=True)
    for density in densities:
        for seed in range(1, args.seeds + 1):
            f = run_flight(args, density, seed, out_dir)
            flights.append(f)
            r = f['report']
            if r:
                print(f"[{len(flights):2d}/{total}] {f['name']:10s} {'ok  ' if r['success'] else 'FAIL'} "
                      f"goals {r['goals_reached']}/{r['goals_total']} collisions {r['collisions']} "
                      f"min clearance {fmt(num(r['min_clearance_m']))} m speed {fmt(num(r['mean_speed_mps']))}/"
                      f"{fmt(num(r['max_speed_mps']))} m/s replans {r['replans']} ({r['replan_failures']} failed) "
                      f"p95 {fmt(num(r['replan_ms_p95']), 1)} ms {fmt(num(r['duration_s']), 1)} s "
                      f"(wall {f['wall_s']:.0f} s){'' if r['success'] else ': ' + r['message']}", flush=True)
            else:
                print(f"[{len(flights):2d}/{total}] {f['name']:10s} NO REPORT (exit {f['rc']}, see {f['log']})", flush=True)

    groups = [(d, aggregate([f for f in flights if f['density'] == d])) for d in densities]
    overall = aggregate(flights)
    groups.append(('overall', overall))
    md = ['# Closed-loop flight benchmark', '',
          f'{len(flights)} flights: densities {", ".join(densities)}, seeds 1..{args.seeds}, max_vel {args.max_vel} m/s, '
          f'{"the three default goals" if args.default_goals else f"{args.goals} seeded random goals at both ends of the forest"}'
          f', goal timeout {args.goal_timeout:.0f} s{", simulated time" if args.sim_time else ""}. '
          'Replanning times pooled over every planning call of the group; min clearance is the smallest over the '
          'flights (body centre to the nearest occupied voxel), mean speed the mean of the flights\' time-averaged '
          'speeds.', '']
    md += summary_table(groups)
    md += ['', '## Flights', '']
    md += flight_table(flights)
    result = (f"RESULT flights={overall['flights']} goals_reached_rate={overall['goals_reached_rate']:.3f} "
              f"collisions={overall['collisions']} min_clearance_m={fmt(overall['min_clearance_m'], 3)} "
              f"mean_speed_mps={fmt(overall['mean_speed_mps'], 2)} replan_ms_median={overall['replan_ms_median']:.2f} "
              f"replan_ms_p95={overall['replan_ms_p95']:.2f}")
    return write_report(args, md, summary_table(groups), result)


if __name__ == '__main__':
    sys.exit(main(sys.argv))
