#!/usr/bin/python3
"""The speed benchmark (make bench-speed): closed-loop flights in the ROS simulation over the six world
styles of make bench-flight x ideal and realistic sensing x max_vel 3, 5 and 7 (goals in the open and
beside obstacles, as bench-flight draws them), one after the other, headless.

Per flight and per group (style, sensing, max_vel): goals, collisions, min clearance, mean speed (on
the ground truth), share of the time at or above 0.8 max_vel, the speed account (the share of the slow
time per cause: held, braking, commitment, takeover, tracking, limits, timing) and mission time /
oracle time (the flight monitor's FlightOracle: the global route on the true map in the planner's
window at the planning clearance, shortened, flown time-optimally along its length at max_vel and
max_acc). Writes OUT/bench_speed.md, OUT/bench_speed_speeds.png (mean speed against max_vel per style)
and ends with
  RESULT flights=... goals_reached_rate=... collisions=... time_ratio_median=... mean_speed_3=...
         mean_speed_5=... mean_speed_7=...
"""
import argparse
import math
import os
import statistics
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import bench_flight  # noqa: E402  (the flight runner and world drawing of make bench-flight)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CAUSES = ['held', 'braking', 'commitment', 'takeover', 'tracking', 'limits', 'timing']


def group(flights):
    reps = [f['report'] for f in flights if f['report']]
    ratios = [r['time_ratio'] for r in reps if r.get('time_ratio') is not None]
    acc = {c: sum(r.get('speed_account_s', {}).get(c, 0.0) for r in reps) for c in CAUSES}
    slow = sum(acc.values())
    clear = [r['min_clearance_m'] for r in reps if r.get('min_clearance_m') is not None]
    return {
        'flights': len(flights), 'no_report': sum(1 for f in flights if not f['report']),
        'goals': sum(r['goals_reached'] for r in reps), 'goals_total': sum(f['goals_total'] for f in flights),
        'collisions': sum(r['collisions'] for r in reps), 'min_clearance': min(clear) if clear else None,
        'mean_speed': statistics.mean([r['mean_speed_mps'] for r in reps]) if reps else None,
        'fast': statistics.mean([r.get('fast_share', 0.0) for r in reps]) if reps else None,
        'ratio_median': statistics.median(ratios) if ratios else None, 'ratio_max': max(ratios) if ratios else None,
        'replans': sum(r['replans'] for r in reps), 'failed': sum(r['replan_failures'] for r in reps),
        'account': {c: (acc[c] / slow if slow > 0 else 0.0) for c in CAUSES},
    }


def fmt(x, d=2):
    return 'n/a' if x is None or (isinstance(x, float) and math.isnan(x)) else f'{x:.{d}f}'


def row(label, g):
    account = ', '.join(f"{c} {100 * g['account'][c]:.0f}" for c in CAUSES if g['account'][c] >= 0.005)
    calls = g['replans'] + g['failed']
    return (f"| {label} | {g['goals']}/{g['goals_total']} | {g['collisions']} | {fmt(g['min_clearance'])} | "
            f"{fmt(g['mean_speed'])} | {100 * (g['fast'] or 0.0):.0f}% | {fmt(g['ratio_median'])} / {fmt(g['ratio_max'])} | "
            f"{g['failed']}/{calls} ({100.0 * g['failed'] / calls if calls else 0.0:.1f}%) | {account} |")


HEADER = ['| group | goals | collisions | min clearance [m] | mean speed [m/s] | time >= 0.8 max_vel | '
          'mission / oracle time, median / max | failed replans | slow time by cause [%] |',
          '|---|---|---|---|---|---|---|---|---|']


def plot(path, styles, vels, flights):
    try:
        import matplotlib
        matplotlib.use('Agg')
        import matplotlib.pyplot as plt
    except ImportError:
        print('bench_speed: no matplotlib, no plot', flush=True)
        return
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for st in styles:
        ys = [group([f for f in flights if f['group'] == st and f['vel'] == v])['mean_speed'] for v in vels]
        ax.plot(vels, [y if y is not None else float('nan') for y in ys], marker='o', label=st)
    ax.plot(vels, vels, color='0.7', linestyle='--', label='max_vel')
    ax.set_xlabel('max_vel [m/s]')
    ax.set_ylabel('mean speed [m/s] (ground truth)')
    ax.set_title('bench-speed: mean speed against max_vel per world style')
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    print(f'bench_speed: wrote {path}', flush=True)


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--out', default=os.path.join(ROOT, 'results'))
    ap.add_argument('--styles', default='forest-medium,forest-high,windows,rings,boxes,mixed')
    ap.add_argument('--sensing', default='ideal,realistic')
    ap.add_argument('--vels', default='3,5,7')
    ap.add_argument('--seeds', type=int, default=1)
    ap.add_argument('--goals', type=int, default=3)
    ap.add_argument('--goal-timeout', type=float, default=90.0)
    ap.add_argument('--sim-time', action='store_true', help='simulated time (lockstep) instead of real time')
    ap.add_argument('--resume', action='store_true', help='reuse the reports of flights already in OUT')
    args = ap.parse_args(argv[1:])
    args.ws = os.environ.get('WS', os.path.join(ROOT, 'build', 'ws'))
    args.no_plot = True
    args.dump_failed_plans = False
    styles = [s.split('-') if '-' in s else [s, 'medium'] for s in args.styles.split(',') if s]
    sensings = [s for s in args.sensing.split(',') if s]
    vels = [float(v) for v in args.vels.split(',') if v]
    cases = [(v, st, de, se, seed) for v in vels for st, de in styles for se in sensings for seed in range(1, args.seeds + 1)]
    print(f'bench_speed: {len(cases)} flights (styles {args.styles}; sensing {args.sensing}; max_vel {args.vels}; seeds '
          f'1..{args.seeds}); files in {os.path.join(args.out, "bench_speed")}', flush=True)
    flights = []
    for v, st, de, se, seed in cases:
        args.max_vel = v
        out_dir = os.path.join(args.out, 'bench_speed', f'v{v:g}')
        os.makedirs(out_dir, exist_ok=True)
        f = bench_flight.run_world_flight(args, st, de, se, seed, out_dir)
        f['group'] = f'{st}-{de}' if st == 'forest' else st
        f['vel'] = v
        flights.append(f)
        r = f['report']
        label = f"{f['group']}/{se}/s{seed}/v{v:g}"
        if r:
            print(f"[{len(flights):3d}/{len(cases)}] {label:32s} {'ok  ' if r['success'] else 'FAIL'} goals {r['goals_reached']}/"
                  f"{r['goals_total']} collisions {r['collisions']} clearance {fmt(r.get('min_clearance_m'))} m mean "
                  f"{fmt(r.get('mean_speed_mps'))} m/s fast {100 * r.get('fast_share', 0.0):.0f}% time/oracle "
                  f"{fmt(r.get('time_ratio'))} (wall {f['wall_s']:.0f} s)", flush=True)
        else:
            print(f"[{len(flights):3d}/{len(cases)}] {label:32s} NO REPORT (see {f['log']})", flush=True)

    group_names = list(dict.fromkeys(f['group'] for f in flights))
    md = ['# Speed benchmark (make bench-speed)', '',
          f"{len(flights)} closed-loop flights: styles {args.styles}, sensing {args.sensing}, max_vel {args.vels} m/s "
          f"(max_acc 2.5 m/s^2), seeds 1..{args.seeds}, {args.goals} goals each (bench-flight's: in the open or beside "
          "obstacles), goal timeout "
          f"{args.goal_timeout:.0f} s. Mean speed and path on the ground truth. Oracle: the global route on the true map in "
          "the planner's window at the planning clearance, shortened, flown time-optimally at max_vel and max_acc.", '']
    for v in vels:
        md += [f'## max_vel {v:g} m/s', ''] + HEADER
        for g in group_names:
            for se in sensings:
                md.append(row(f'{g} / {se}', group([f for f in flights if f['vel'] == v and f['group'] == g and f['sensing'] == se])))
        md.append(row('**all**', group([f for f in flights if f['vel'] == v])))
        md.append('')
    md += ['## Mean speed against max_vel', '', '| style | ' + ' | '.join(f'max_vel {v:g}' for v in vels) + ' |',
           '|---|' + '---|' * len(vels)]
    for g in group_names:
        md.append(f'| {g} | ' + ' | '.join(fmt(group([f for f in flights if f['vel'] == v and f['group'] == g])['mean_speed'])
                                           for v in vels) + ' |')
    md += ['', '## Flights', '', '| flight | max_vel | result | goals | collisions | min clearance | mean speed | '
           'time >= 0.8 max_vel | mission / oracle | failed replans |', '|---|---|---|---|---|---|---|---|---|---|']
    for f in flights:
        r = f['report']
        if not r:
            md.append(f"| {f['name']} | {f['vel']:g} | no report | | | | | | | |")
            continue
        md.append(f"| {f['name']} | {f['vel']:g} | {'ok' if r['success'] else r['status']} | {r['goals_reached']}/"
                  f"{r['goals_total']} | {r['collisions']} | {fmt(r.get('min_clearance_m'))} | {fmt(r.get('mean_speed_mps'))} | "
                  f"{100 * r.get('fast_share', 0.0):.0f}% | {fmt(r.get('time_ratio'))} | {r['replan_failures']}/"
                  f"{r['replans'] + r['replan_failures']} |")
    allg = group(flights)
    speeds = ' '.join(f"mean_speed_{v:g}={fmt(group([f for f in flights if f['vel'] == v])['mean_speed'])}" for v in vels)
    result = (f"RESULT flights={len(flights)} goals_reached_rate={allg['goals'] / max(1, allg['goals_total']):.3f} "
              f"collisions={allg['collisions']} min_clearance_m={fmt(allg['min_clearance'], 3)} "
              f"time_ratio_median={fmt(allg['ratio_median'])} {speeds}")
    md += ['', '```', result, '```', '']
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, 'bench_speed.md'), 'w') as fh:
        fh.write('\n'.join(md))
    plot(os.path.join(args.out, 'bench_speed_speeds.png'), group_names, vels, flights)
    print('\n'.join(HEADER + [row(f'all v{v:g}', group([f for f in flights if f['vel'] == v])) for v in vels]))
    print(f"bench_speed: wrote {os.path.join(args.out, 'bench_speed.md')}")
    print(result)
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv))
