#!/usr/bin/python3
"""Fault-injection flight benchmark (make bench-faults; not in CI): seeded closed-loop flights, each
with a random schedule of the faults the simulator injects (uav_sim/fault_schedule.h) plus planner
kills, and the same flights without faults as the control; aggregates the flight monitor's reports.

Each flight: scripts/run_flight.sh in simulated time with the lockstep controller, a seeded medium
forest, two goals (x = +15 then x = -15, y in [-6, 6], z in [0.8, 1.6]; start (-15, 0, 1)), and 1-2
faults of distinct kinds drawn with the flight's seed:
  depth_blackout   the camera sends nothing for 1-4 s
  odom_blackout    odometry and tf stop for 0.5-3 s (the controller falls silent: failsafe hold)
  odom_jump        the odometry position jumps by 0.3-1.5 m (horizontal, any direction)
  clock_step       /clock and every stamp jump by -3..-0.5 or +0.5..+5 s
  planner_kill     the planner node is killed (rosnode's API) and respawned by roslaunch
at 1-8 s after the vehicle first flies faster than 0.5 m/s. The schedule is written to
OUT/bench_faults/<name>_faults.json before the flight; the monitor's files are there too.

A fault counts as handled when its flight had no collision, no setpoint jump (a step over
|v| dt + 5 cm that is not a re-anchoring), the worst commanded deceleration within
max_brake_acc + margin (5 + 1 m/s^2; not across a re-anchoring, which sets the command to the
measured state, velocity included), and completed its mission (every goal reached) once the fault
cleared. Writes OUT/bench_faults.md (a table per fault kind, the control, one row per flight) and
ends with one line:
  RESULT flights=... faults_injected=... collisions=... setpoint_jumps=... missions_completed_rate=...
         min_clearance_m=...
(over the flights with faults; the control's figures are in the table).
"""
import argparse
import json
import math
import os
import random
import socket
import struct
import subprocess
import sys
import threading
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
KINDS = ['depth_blackout', 'odom_blackout', 'odom_jump', 'clock_step', 'planner_kill']
START_ON_SPEED_MPS = 0.5
MAX_BRAKE_ACC_MPS2 = 5.0
DECEL_MARGIN_MPS2 = 1.0


def num(x):
    try:
        return float(x)
    except (TypeError, ValueError):
        return math.nan


def fmt(x, d=2):
    return 'n/a' if x is None or (isinstance(x, float) and math.isnan(x)) else f'{x:.{d}f}'


def mission(seed):
    rng = random.Random(f'mission-{seed}')
    return [15.0, round(rng.uniform(-6.0, 6.0), 2), round(rng.uniform(0.8, 1.6), 2),
            -15.0, round(rng.uniform(-6.0, 6.0), 2), round(rng.uniform(0.8, 1.6), 2)]


def schedule(seed):
    """The flight's faults: 1-2 distinct kinds, times from the first motion (faults_start_on_speed)."""
    rng = random.Random(f'faults-{seed}')
    kinds = rng.sample(KINDS, rng.choice([1, 2]))
    s = {'seed': seed, 'kinds': kinds, 'start_on_speed_mps': START_ON_SPEED_MPS, 'depth_blackouts': [],
         'odom_blackouts': [], 'odom_jumps': [], 'clock_steps': [], 'planner_kill_s': None}
    for kind in kinds:
        t = round(rng.uniform(1.0, 8.0), 2)
        if kind == 'depth_blackout':
            s['depth_blackouts'] += [t, round(t + rng.uniform(1.0, 4.0), 2)]
        elif kind == 'odom_blackout':
            s['odom_blackouts'] += [t, round(t + rng.uniform(0.5, 3.0), 2)]
        elif kind == 'odom_jump':
            a, m = rng.uniform(-math.pi, math.pi), rng.uniform(0.3, 1.5)
            s['odom_jumps'] += [t, round(m * math.cos(a), 3), round(m * math.sin(a), 3), 0.0]
        elif kind == 'clock_step':
            step = -rng.uniform(0.5, 3.0) if rng.random() < 0.5 else rng.uniform(0.5, 5.0)
            s['clock_steps'] += [t, round(max(step, -(t + 0.9)), 3)]  # the ROS time stays positive
        elif kind == 'planner_kill':
            s['planner_kill_s'] = t
    return s


def yaml_list(values):
    return '[' + ', '.join(str(v) for v in values) + ']'


def free_port():
    s = socket.socket()
    s.bind(('127.0.0.1', 0))
    port = s.getsockname()[1]
    s.close()
    return port


def odometry_speed(buf):
    """|v| of a serialised nav_msgs/Odometry (Debian's ROS has no Python nav_msgs; see
    plan_manage/test/fault_test.py)."""
    def skip_string(offset):
        (n,) = struct.unpack_from('<I', buf, offset)
        return offset + 4 + n
    o = skip_string(skip_string(12))
    vx, vy, vz = struct.unpack_from('<3d', buf, o + 8 * (7 + 36))
    return math.sqrt(vx * vx + vy * vy + vz * vz)


def kill_planner_after(kill_after_s):
    """The planner killer (bench_faults.py --kill-planner-after S, run with the flight's master in
    ROS_MASTER_URI): counts ground-truth messages (200 Hz of simulated time, also through odometry
    blackouts and clock steps) from the first one faster than 0.5 m/s and kills /planner (rosnode's
    API) kill_after_s later; roslaunch respawns it."""
    import rosnode
    import rospy
    state = {'count': -1, 'done': False}

    def on_truth(msg):
        if state['done']:
            return
        if state['count'] < 0:
            if odometry_speed(msg._buff) > START_ON_SPEED_MPS:
                state['count'] = 0
            return
        state['count'] += 1
        if state['count'] * 0.005 >= kill_after_s:
            state['done'] = True
            print(f'bench_faults: killing /planner {kill_after_s} s after the first motion', flush=True)
            rosnode.kill_nodes(['/planner'])

    rospy.init_node('bench_faults_killer', anonymous=True, disable_signals=True)
    rospy.Subscriber('/quadrotor_sim/ground_truth', rospy.AnyMsg, on_truth, queue_size=400)
    while not rospy.is_shutdown() and not state['done']:
        time.sleep(0.1)
    return 0


def planner_killer(port, kill_after_s, log, stop):
    """Runs the killer in its own process (rospy takes one master per process) once the flight's
    master answers; stops it when the flight ends."""
    env = dict(os.environ, ROS_MASTER_URI=f'http://127.0.0.1:{port}', ROS_HOSTNAME='127.0.0.1')
    env.pop('ROS_IP', None)
    while not stop.is_set():
        try:
            with socket.create_connection(('127.0.0.1', port), timeout=1.0):
                break
        except OSError:
            time.sleep(0.5)
    if stop.is_set():
        return
    p = subprocess.Popen(['/usr/bin/python3', os.path.abspath(__file__), '--kill-planner-after', str(kill_after_s)],
                         env=env, stdout=log, stderr=subprocess.STDOUT)
    while p.poll() is None and not stop.is_set():
        time.sleep(0.5)
    if p.poll() is None:
        p.terminate()
        try:
            p.wait(timeout=10)
        except subprocess.TimeoutExpired:
            p.kill()


def run_flight(args, seed, faults, out_dir):
    name = f'medium_s{seed}' + ('_faults' if faults else '_control')
    port = free_port()
    cmd = ['bash', os.path.join(ROOT, 'scripts', 'run_flight.sh'), '--density', 'medium', '--seed', str(seed),
           '--max-vel', str(args.max_vel), '--goal-timeout', str(args.goal_timeout), '--output-dir', out_dir,
           '--name', name, '--rviz', 'false', '--sim-time', 'true', '--realtime-factor', str(args.realtime_factor),
           '--master-port', str(port), '--goals', ' '.join(str(g) for g in mission(seed)), '--no-plot', '--']
    if faults:
        with open(os.path.join(out_dir, name + '_faults.json'), 'w') as f:
            json.dump(faults, f, indent=2)
        cmd += [f"depth_blackouts:={yaml_list(faults['depth_blackouts'])}",
                f"odom_blackouts:={yaml_list(faults['odom_blackouts'])}",
                f"odom_jumps:={yaml_list(faults['odom_jumps'])}",
                f"clock_steps:={yaml_list(faults['clock_steps'])}",
                f"faults_start_on_speed:={faults['start_on_speed_mps']}"]
        if faults['planner_kill_s'] is not None:
            cmd.append('planner_respawn:=true')
    t0 = time.time()
    log_path = os.path.join(out_dir, name + '.log')
    with open(log_path, 'w') as log:
        stop = threading.Event()
        killer = None
        if faults and faults['planner_kill_s'] is not None:
            killer = threading.Thread(target=planner_killer, args=(port, faults['planner_kill_s'], log, stop))
            killer.start()
        rc = subprocess.call(cmd, stdout=log, stderr=subprocess.STDOUT)
        stop.set()
        if killer:
            killer.join()
    wall = time.time() - t0
    report = None
    path = os.path.join(out_dir, name + '_report.json')
    if os.path.exists(path):
        with open(path) as f:
            report = json.load(f)
    return {'name': name, 'seed': seed, 'faults': faults, 'rc': rc, 'wall_s': wall, 'report': report, 'log': log_path}


def injected_kinds(f):
    """Fault kinds injected during the flight (the monitor's records; planner kills from its restarts)."""
    r = f['report']
    if not r or not f['faults']:
        return []
    kinds = []
    for rec in r.get('faults', []):
        if rec['goal_index'] >= 0 and rec['phase'] in ('start', 'step'):
            kinds.append(rec['kind'])
    if f['faults']['planner_kill_s'] is not None and r.get('planner_restarts', 0) > 0:
        kinds.append('planner_kill')
    return kinds


def handled(f):
    r = f['report']
    return bool(r) and r['collisions'] == 0 and r['setpoint_jumps'] == 0 and \
        num(r['max_decel_mps2']) <= MAX_BRAKE_ACC_MPS2 + DECEL_MARGIN_MPS2 and r['goals_reached'] == r['goals_total']


def completed(f):
    r = f['report']
    return bool(r) and r['goals_reached'] == r['goals_total']


def aggregate(flights):
    with_report = [f for f in flights if f['report']]
    clear = [num(f['report']['min_clearance_m']) for f in with_report]
    clear = [c for c in clear if not math.isnan(c)]
    decel = [num(f['report']['max_decel_mps2']) for f in with_report]
    return {
        'flights': len(flights),
        'no_report': len(flights) - len(with_report),
        'collisions': sum(f['report']['collisions'] for f in with_report),
        'setpoint_jumps': sum(f['report']['setpoint_jumps'] for f in with_report),
        'reanchorings': sum(f['report']['reanchorings'] for f in with_report),
        'min_clearance_m': min(clear) if clear else math.nan,
        'max_decel_mps2': max(decel) if decel else math.nan,
        'completed': sum(1 for f in flights if completed(f)),
        'handled': sum(1 for f in flights if handled(f)),
        'mean_speed_mps': (sum(num(f['report']['mean_speed_mps']) for f in with_report) / len(with_report)
                           if with_report else math.nan),
    }


def kind_table(faulted, control):
    lines = ['| fault | injected | handled | collisions | setpoint jumps (re-anchorings) | min clearance [m] | '
             'worst decel [m/s^2] | missions completed after it cleared |',
             '|---|---|---|---|---|---|---|---|']
    for kind in KINDS:
        flights = [f for f in faulted if kind in injected_kinds(f)]
        n = sum(injected_kinds(f).count(kind) for f in flights)
        a = aggregate(flights)
        rate = a['completed'] / len(flights) if flights else math.nan
        lines.append(f"| {kind} | {n} | {sum(injected_kinds(f).count(kind) for f in flights if handled(f))} | "
                     f"{a['collisions']} | {a['setpoint_jumps']} ({a['reanchorings']}) | {fmt(a['min_clearance_m'])} | "
                     f"{fmt(a['max_decel_mps2'])} | {a['completed']}/{len(flights)} ({fmt(rate, 2)}) |")
    for label, flights in (('all faulted flights', faulted), ('control (no faults)', control)):
        if not flights:
            continue
        a = aggregate(flights)
        n = sum(len(injected_kinds(f)) for f in flights)
        lines.append(f"| **{label}** | {n} | {a['handled']}/{a['flights']} flights | {a['collisions']} | "
                     f"{a['setpoint_jumps']} ({a['reanchorings']}) | {fmt(a['min_clearance_m'])} | "
                     f"{fmt(a['max_decel_mps2'])} | {a['completed']}/{a['flights']} |")
    return lines


def flight_table(flights):
    lines = ['| flight | faults | result | goals | collisions | jumps (re-anch.) | min clearance [m] | worst decel '
             '[m/s^2] | planner restarts | goals re-sent | time steps | mean speed [m/s] | wall [s] |',
             '|---|---|---|---|---|---|---|---|---|---|---|---|---|']
    for f in flights:
        r = f['report']
        faults = ', '.join(f['faults']['kinds']) if f['faults'] else '-'
        if not r:
            lines.append(f"| {f['name']} | {faults} | no report (exit {f['rc']}, {os.path.basename(f['log'])}) | | | | | | "
                         f"| | | | {fmt(f['wall_s'], 0)} |")
            continue
        lines.append(f"| {f['name']} | {faults} | {'handled' if handled(f) else r['status']} | "
                     f"{r['goals_reached']}/{r['goals_total']} | {r['collisions']} | {r['setpoint_jumps']} "
                     f"({r['reanchorings']}) | {fmt(num(r['min_clearance_m']))} | {fmt(num(r['max_decel_mps2']))} | "
                     f"{r['planner_restarts']} | {r['goal_resends']} | {r['time_steps']} | "
                     f"{fmt(num(r['mean_speed_mps']))} | {fmt(f['wall_s'], 0)} |")
    return lines


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--out', default=os.path.join(ROOT, 'results'), help='results directory')
    ap.add_argument('--flights', type=int, default=20, help='flights with faults (seeds 1..N), each also flown as control')
    ap.add_argument('--first-seed', type=int, default=1)
    ap.add_argument('--max-vel', type=float, default=3.0)
    ap.add_argument('--goal-timeout', type=float, default=60.0)
    ap.add_argument('--realtime-factor', type=float, default=1.0, help='simulated seconds per wall second')
    ap.add_argument('--no-control', action='store_true', help='skip the control flights')
    ap.add_argument('--kill-planner-after', type=float, default=None, help=argparse.SUPPRESS)  # the killer process
    args = ap.parse_args(argv[1:])
    if args.kill_planner_after is not None:
        return kill_planner_after(args.kill_planner_after)

    out_dir = os.path.join(args.out, 'bench_faults')
    os.makedirs(out_dir, exist_ok=True)
    seeds = list(range(args.first_seed, args.first_seed + args.flights))
    total = len(seeds) * (1 if args.no_control else 2)
    print(f'bench_faults: {len(seeds)} flights with faults{"" if args.no_control else " + the same without"}, '
          f'max_vel {args.max_vel} m/s, real-time factor {args.realtime_factor}; files in {out_dir}', flush=True)
    faulted, control = [], []
    k = 0
    for seed in seeds:
        runs = [(schedule(seed), faulted)] + ([] if args.no_control else [(None, control)])
        for faults, into in runs:
            f = run_flight(args, seed, faults, out_dir)
            into.append(f)
            k += 1
            r = f['report']
            what = ', '.join(faults['kinds']) if faults else 'control'
            if r:
                print(f"[{k:2d}/{total}] {f['name']:22s} {what:28s} {'handled' if handled(f) else 'NOT HANDLED':11s} "
                      f"goals {r['goals_reached']}/{r['goals_total']} collisions {r['collisions']} jumps "
                      f"{r['setpoint_jumps']} ({r['reanchorings']} re-anch.) min clearance "
                      f"{fmt(num(r['min_clearance_m']))} m decel {fmt(num(r['max_decel_mps2']))} m/s^2 "
                      f"(wall {f['wall_s']:.0f} s){'' if completed(f) else ': ' + r['message']}", flush=True)
            else:
                print(f"[{k:2d}/{total}] {f['name']:22s} {what:28s} NO REPORT (exit {f['rc']}, see {f['log']})", flush=True)

    a = aggregate(faulted)
    n_faults = sum(len(injected_kinds(f)) for f in faulted)
    rate = a['completed'] / a['flights'] if a['flights'] else 0.0
    result = (f"RESULT flights={a['flights']} faults_injected={n_faults} collisions={a['collisions']} "
              f"setpoint_jumps={a['setpoint_jumps']} missions_completed_rate={rate:.3f} "
              f"min_clearance_m={fmt(a['min_clearance_m'], 3)}")
    md = ['# Fault-injection flight benchmark', '',
          f'{len(faulted)} seeded flights (medium forest, seeds {seeds[0]}..{seeds[-1]}, two goals, max_vel '
          f'{args.max_vel} m/s, simulated time at {args.realtime_factor} x real time with the lockstep controller), '
          f'each with 1-2 random faults at 1-8 s after the first motion (schedules in bench_faults/<flight>_faults.json)'
          f'{"" if args.no_control else ", and the same flights without faults as the control"}. A fault is handled '
          f'when its flight had no collision, no setpoint jump (a step over |v| dt + 5 cm that is not a re-anchoring '
          f'onto the measured state), a worst commanded deceleration within {MAX_BRAKE_ACC_MPS2:.0f} + '
          f'{DECEL_MARGIN_MPS2:.0f} m/s^2 (not across a re-anchoring, which sets the command to the measured '
          f'state, velocity included), and completed its mission. Minimum clearance: body centre to the nearest '
          f'occupied voxel of the true map (body radius 0.15 m).', '']
    md += kind_table(faulted, control)
    md += ['', '## Flights', '']
    md += flight_table(faulted + control)
    md += ['', '```', result, '```', '']
    md_path = os.path.join(args.out, 'bench_faults.md')
    with open(md_path, 'w') as f:
        f.write('\n'.join(md))
    print()
    print('\n'.join(kind_table(faulted, control)))
    print(f'bench_faults: wrote {md_path}')
    print(result)
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv))
