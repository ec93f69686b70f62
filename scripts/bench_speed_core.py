#!/usr/bin/python3
"""The speed benchmark in the ROS-free closed loop (make bench-speed-core): plan_manage's sim_flight flies
the worlds of make bench-flight (path_searching's flight_world: six styles, seeded, a mission there and
back) at several max_vel, in simulated time, a few flights at once. Seconds per flight instead of the
ROS simulation's minutes: the development loop of the speed work; make bench-speed is the referee.

Per flight and per style: goals, collisions, min clearance, mean speed, share of time above 0.8 max_vel,
mission time / oracle time, emergency stops, failed plans, the planning time (the wall time of each
FSM tick that planned, and the replanner's part of it: the ticks' surplus is the route search and
the commit), the speed account. Ends with
  RESULT flights=... goals_reached_rate=... collisions=... time_ratio_median=... mean_speed_3=... ...
  tick_ms_median=... tick_ms_p95=... replanner_ms_median=... replanner_ms_p95=...
"""
import argparse
import concurrent.futures
import json
import os
import statistics
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CAUSES = ['held', 'braking', 'commitment', 'takeover', 'tracking', 'limits', 'timing']


def world(ws, out_dir, style, seed, goals):
    kind, density = (style.split('-') + ['medium'])[:2]
    bt = os.path.join(out_dir, f'{style}_s{seed}.bt')
    tool = os.path.join(ws, 'devel', 'lib', 'topo_planner', 'flight_world')
    r = subprocess.run([tool, '--style', kind, '--density', density, '--seed', str(seed), '--goals', str(goals),
                        '--out', bt], capture_output=True, text=True)
    lines = dict(l.split(' ', 1) for l in r.stdout.splitlines() if ' ' in l)
    if r.returncode != 0 or 'GOALS' not in lines:
        raise RuntimeError(f'flight_world {style} {seed}: {r.stderr.strip()}')
    return bt, lines['GOALS']


def fly(args, style, seed, sensing, vel, bt, goals):
    name = f'{style}_{sensing}_s{seed}_v{vel:g}'
    js = os.path.join(args.out, name + '.json')
    cmd = [os.path.join(args.ws, 'devel', 'lib', 'topo_planner', 'sim_flight'), '--map', bt, '--goals', goals,
           '--max-vel', str(vel), '--sensing', sensing, '--json', js, '--quiet', '--goal-timeout', str(args.goal_timeout)]
    if args.trace:
        cmd += ['--trace', os.path.join(args.out, name + '.csv')]
    if args.config:
        cmd += ['--config', args.config]
    for p in args.param:
        cmd += ['--param', p]
    subprocess.run(cmd, capture_output=True, text=True)
    try:
        with open(js) as f:
            r = json.load(f)
    except (OSError, ValueError):
        r = None
    return {'name': name, 'style': style, 'seed': seed, 'sensing': sensing, 'vel': vel, 'r': r}


def fmt(x, d=2):
    return 'n/a' if x is None else f'{x:.{d}f}'


def summary(flights):
    ok = [f['r'] for f in flights if f['r']]
    ratios = [r['time_ratio'] for r in ok if r['time_ratio'] is not None]
    acc = {c: sum(r['speed_account_s'][c] for r in ok) for c in CAUSES}
    slow = sum(acc.values())
    return {
        'flights': len(flights), 'goals': sum(r['goals_reached'] for r in ok), 'goals_total': sum(r['goals_total'] for r in ok),
        'collisions': sum(r['collisions'] for r in ok), 'min_clearance': min((r['min_clearance_m'] for r in ok), default=None),
        'mean_speed': statistics.mean([r['mean_speed_mps'] for r in ok]) if ok else None,
        'fast': statistics.mean([r['fast_share'] for r in ok]) if ok else None,
        'ratio_median': statistics.median(ratios) if ratios else None, 'ratio_max': max(ratios, default=None),
        'stops': sum(r['emergency_stops'] for r in ok), 'failed': sum(r['replan_failures'] for r in ok),
        'calls': sum(r['replans'] + r['replan_failures'] for r in ok),
        'account': {c: (acc[c] / slow if slow > 0 else 0.0) for c in CAUSES},
        'tick_ms': [m for r in ok for m in r.get('replan_ms', [])],
        'planner_ms': [m for r in ok for m in r.get('planner_ms', [])],
    }


def pct(v, q):
    v = sorted(v)
    return v[min(len(v) - 1, int(q * (len(v) - 1) + 0.5))] if v else None


def row(label, s):
    account = ' '.join(f"{c[:4]} {100 * s['account'][c]:.0f}" for c in CAUSES if s['account'][c] >= 0.005)
    return (f"| {label} | {s['goals']}/{s['goals_total']} | {s['collisions']} | {fmt(s['min_clearance'])} | "
            f"{fmt(s['mean_speed'])} | {100 * (s['fast'] or 0):.0f}% | {fmt(s['ratio_median'])} / {fmt(s['ratio_max'])} | "
            f"{s['stops']} | {s['failed']}/{s['calls']} | {fmt(pct(s['tick_ms'], 0.5))} / {fmt(pct(s['tick_ms'], 0.95))} | "
            f"{fmt(pct(s['planner_ms'], 0.5))} / {fmt(pct(s['planner_ms'], 0.95))} | {account} |")


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--out', default=os.path.join(ROOT, 'results', 'speed_core'))
    ap.add_argument('--styles', default='forest-medium,forest-high,windows,rings,boxes,mixed')
    ap.add_argument('--seeds', type=int, default=1)
    ap.add_argument('--sensing', default='ideal')
    ap.add_argument('--vels', default='3,5,7')
    ap.add_argument('--goals', type=int, default=2, help='goals per mission (there and back: 2)')
    ap.add_argument('--goal-timeout', type=float, default=90.0)
    ap.add_argument('--jobs', type=int, default=2)
    ap.add_argument('--trace', action='store_true', help='a CSV trace per flight')
    ap.add_argument('--param', action='append', default=[], help='name=value: a config/planner.yaml override')
    ap.add_argument('--config', default='', help='a config directory instead of config/ (e.g. another mapping.yaml)')
    args = ap.parse_args(argv[1:])
    args.ws = os.environ.get('WS', os.path.join(ROOT, 'build', 'ws'))
    os.makedirs(args.out, exist_ok=True)
    styles = [s for s in args.styles.split(',') if s]
    vels = [float(v) for v in args.vels.split(',') if v]
    sensings = [s for s in args.sensing.split(',') if s]
    worlds = {(st, seed): world(args.ws, args.out, st, seed, args.goals) for st in styles for seed in range(1, args.seeds + 1)}
    cases = [(st, seed, se, v) for v in vels for st in styles for se in sensings for seed in range(1, args.seeds + 1)]
    print(f'bench_speed_core: {len(cases)} flights ({", ".join(styles)}; {", ".join(sensings)}; max_vel {args.vels}; '
          f'seeds 1..{args.seeds})', flush=True)
    flights = []
    with concurrent.futures.ThreadPoolExecutor(max_workers=args.jobs) as pool:
        futures = [pool.submit(fly, args, st, seed, se, v, *worlds[(st, seed)]) for st, seed, se, v in cases]
        for fut in futures:
            f = fut.result()
            flights.append(f)
            r = f['r']
            if r:
                print(f"  {f['name']:34s} goals {r['goals_reached']}/{r['goals_total']} coll {r['collisions']} "
                      f"clear {r['min_clearance_m']:.2f} mean {r['mean_speed_mps']:.2f} ratio {fmt(r['time_ratio'])} "
                      f"stops {r['emergency_stops']} failed {r['replan_failures']}", flush=True)
            else:
                print(f"  {f['name']:34s} NO RESULT", flush=True)
    header = ['| group | goals | collisions | min clearance [m] | mean speed [m/s] | fast | time / oracle median / max | '
              'stops | failed plans | planning tick ms median / p95 | replanner ms median / p95 | slow time by cause [%] |',
              '|---|---|---|---|---|---|---|---|---|---|---|---|']
    lines = header[:]
    for v in vels:
        for st in styles:
            lines.append(row(f'{st} v{v:g}', summary([f for f in flights if f['style'] == st and f['vel'] == v])))
        lines.append(row(f'**all v{v:g}**', summary([f for f in flights if f['vel'] == v])))
    print('\n'.join(lines))
    all_s = summary(flights)
    speeds = ' '.join(f"mean_speed_{v:g}={fmt(summary([f for f in flights if f['vel'] == v])['mean_speed'])}" for v in vels)
    print(f"RESULT flights={len(flights)} goals_reached_rate={all_s['goals'] / max(1, all_s['goals_total']):.3f} "
          f"collisions={all_s['collisions']} min_clearance_m={fmt(all_s['min_clearance'], 3)} "
          f"time_ratio_median={fmt(all_s['ratio_median'])} stops={all_s['stops']} {speeds} "
          f"tick_ms_median={fmt(pct(all_s['tick_ms'], 0.5))} tick_ms_p95={fmt(pct(all_s['tick_ms'], 0.95))} "
          f"replanner_ms_median={fmt(pct(all_s['planner_ms'], 0.5))} replanner_ms_p95={fmt(pct(all_s['planner_ms'], 0.95))}")
    with open(os.path.join(args.out, 'bench_speed_core.md'), 'w') as f:
        f.write('\n'.join(lines) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv))
