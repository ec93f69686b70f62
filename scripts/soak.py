#!/usr/bin/python3
"""Soak flight (make soak; not in CI): one continuous simulated mission of --minutes of simulated
time (default 30) through a seeded high-density forest, goals cycling between its two ends, in
simulated time with the lockstep controller at --realtime-factor (default 1.5: faster than real
time where the machine keeps up; the lockstep makes the flight the same either way). Every
--sample-s of simulated time (default 10) it samples each node's resident memory (VmRSS) and CPU
(utime + stime over the wall time between samples), and the planner's replanning times.

Prints a table per node (RSS at the start, the middle and the end, the growth over the second half,
mean and max CPU), the replanning time per fifth of the flight (median and p95) with the slope of a
least-squares line through all calls, and one line:
  RESULT sim_minutes=... goals=... collisions=... rss_growth_mb_max=... planner_cpu_mean=...
         replan_ms_slope_per_hour=...
Targets (issue 14): no collision, every node's RSS growth over the second half under 5 MB, no rising
trend in replanning time. Writes OUT/soak.md and OUT/soak_samples.csv.

Run in a sourced workspace (make soak does): it reads /planning/replan_event with the package's
generated messages.
"""
import argparse
import os
import re
import signal
import statistics
import subprocess
import sys
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_faults import free_port, yaml_list  # noqa: E402
from bench_flight import random_goals  # noqa: E402

NODES = ['planner_node', 'traj_server_node', 'quadrotor_sim_node', 'geometric_controller_node',
         'depth_camera_node', 'map_generator_node', 'flight_monitor_node']
TICKS = os.sysconf('SC_CLK_TCK')


def node_pids(launch_pid):
    """{node executable: pid} of the launch's children (by /proc)."""
    found = {}
    for pid in os.listdir('/proc'):
        if not pid.isdigit():
            continue
        try:
            with open(f'/proc/{pid}/cmdline', 'rb') as f:
                argv = f.read().split(b'\0')
        except OSError:
            continue
        exe = os.path.basename(argv[0].decode(errors='replace')) if argv and argv[0] else ''
        if exe in NODES:
            found[exe] = int(pid)
    return found


def sample(pid):
    """(rss MB, cpu seconds) of a process, or None when it is gone."""
    try:
        with open(f'/proc/{pid}/status') as f:
            rss_kb = next(int(line.split()[1]) for line in f if line.startswith('VmRSS:'))
        with open(f'/proc/{pid}/stat') as f:
            fields = f.read().rsplit(')', 1)[1].split()
        cpu = (int(fields[11]) + int(fields[12])) / TICKS  # utime, stime
        return rss_kb / 1024.0, cpu
    except (OSError, StopIteration, IndexError, ValueError):
        return None


def pct(values, q):
    v = sorted(values)
    return v[min(len(v) - 1, int(q * len(v)))] if v else float('nan')


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--out', default='results')
    ap.add_argument('--minutes', type=float, default=30.0, help='simulated minutes')
    ap.add_argument('--realtime-factor', type=float, default=1.5)
    ap.add_argument('--sample-s', type=float, default=10.0, help='simulated seconds between samples')
    ap.add_argument('--density', default='high')
    ap.add_argument('--seed', type=int, default=1)
    ap.add_argument('--max-vel', type=float, default=2.5)
    args = ap.parse_args(argv[1:])
    os.makedirs(args.out, exist_ok=True)

    port = free_port()
    env = dict(os.environ, ROS_MASTER_URI=f'http://127.0.0.1:{port}', ROS_HOSTNAME='127.0.0.1')
    os.environ.update(ROS_MASTER_URI=env['ROS_MASTER_URI'], ROS_HOSTNAME='127.0.0.1')
    n_goals = max(4, int(args.minutes * 60 / 12) + 4)  # a leg of ~30 m takes ~20 s: more than enough
    g = random_goals(args.density, args.seed, n_goals)
    cmd = ['roslaunch', '-p', str(port), 'topo_planner', 'simulation.launch', 'rviz:=false', 'sim_time:=true',
           f'realtime_factor:={args.realtime_factor}', f'density:={args.density}', f'seed:={args.seed}',
           f'max_vel:={args.max_vel}', 'monitor:=true', 'shutdown_when_done:=true', 'output:=log',
           'goal_timeout:=120', f'output_dir:={args.out}', 'name:=soak', f'goals:={yaml_list(g)}']
    log = open(os.path.join(args.out, 'soak_launch.log'), 'w')
    launch = subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)

    import rospy
    from rosgraph_msgs.msg import Clock, Log
    from topo_planner.msg import ReplanEvent
    for _ in range(300):
        try:
            rospy.get_master().getPid()
            break
        except Exception:
            time.sleep(0.1)
    rospy.init_node('soak', anonymous=True, disable_signals=True)
    lock = threading.Lock()
    state = {'sim': 0.0, 'goals': 0, 'collisions': 0, 'calls': []}

    def on_clock(msg):
        with lock:
            state['sim'] = msg.clock.to_sec()

    def on_log(msg):
        text = msg.msg
        with lock:
            if msg.name.endswith('flight_monitor') and re.search(r'goal \d+/\d+ .* reached at', text):
                state['goals'] += 1
            if msg.name.endswith('quadrotor_sim') and text.startswith('quadrotor_sim: collision'):
                state['collisions'] += 1

    def on_event(msg):
        with lock:
            state['calls'].append((state['sim'], msg.total_ms))

    rospy.Subscriber('/clock', Clock, on_clock, queue_size=1)
    rospy.Subscriber('/rosout', Log, on_log, queue_size=1000)
    rospy.Subscriber('/planning/replan_event', ReplanEvent, on_event, queue_size=1000)

    samples = []  # (sim s, wall s, node, rss MB, cpu s)
    end_sim = args.minutes * 60.0
    next_sample = 0.0
    wall0 = time.monotonic()
    print(f'soak: {args.minutes:.0f} simulated minutes, {args.density} forest seed {args.seed}, realtime factor '
          f'{args.realtime_factor}, {n_goals} goals; master on port {port}', flush=True)
    while launch.poll() is None:
        with lock:
            sim = state['sim']
        if sim >= next_sample:
            wall = time.monotonic() - wall0
            for node, pid in node_pids(launch.pid).items():
                s = sample(pid)
                if s:
                    samples.append((sim, wall, node, s[0], s[1]))
            next_sample = sim + args.sample_s
            if int(sim) % 300 < args.sample_s:
                with lock:
                    print(f'soak: t = {sim / 60:.1f} min, {state["goals"]} goals, {state["collisions"]} collisions, '
                          f'{len(state["calls"])} planning calls', flush=True)
        if sim >= end_sim:
            break
        time.sleep(0.2)
    ended_early = launch.poll() is not None
    try:
        os.killpg(launch.pid, signal.SIGINT)
        launch.wait(timeout=60)
    except (ProcessLookupError, subprocess.TimeoutExpired):
        launch.kill()
    with lock:
        sim, n_goals_done, collisions, calls = state['sim'], state['goals'], state['collisions'], list(state['calls'])

    # Per node: RSS start / middle / end, growth over the second half, CPU mean / max.
    rows, growth_max = [], 0.0
    with open(os.path.join(args.out, 'soak_samples.csv'), 'w') as f:
        f.write('sim_s,wall_s,node,rss_mb,cpu_s\n')
        for s in samples:
            f.write(f'{s[0]:.1f},{s[1]:.1f},{s[2]},{s[3]:.2f},{s[4]:.2f}\n')
    planner_cpu = float('nan')
    for node in NODES:
        ss = [s for s in samples if s[2] == node]
        if len(ss) < 3:
            continue
        mid = ss[len(ss) // 2]
        growth = ss[-1][3] - mid[3]
        growth_max = max(growth_max, growth)
        cpus = [100.0 * (b[4] - a[4]) / max(1e-6, b[1] - a[1]) for a, b in zip(ss, ss[1:])]
        rows.append((node, ss[0][3], mid[3], ss[-1][3], growth, statistics.mean(cpus), max(cpus)))
        if node == 'planner_node':
            planner_cpu = statistics.mean(cpus)
    lines = [f'# Soak flight: {sim / 60:.1f} simulated minutes ({args.density} forest, seed {args.seed}, realtime '
             f'factor {args.realtime_factor}{", ended early" if ended_early else ""})', '',
             '| node | RSS start [MB] | RSS middle [MB] | RSS end [MB] | growth over the second half [MB] | CPU mean [%] | CPU max [%] |',
             '|---|---|---|---|---|---|---|']
    lines += [f'| {r[0]} | {r[1]:.1f} | {r[2]:.1f} | {r[3]:.1f} | {r[4]:+.2f} | {r[5]:.1f} | {r[6]:.1f} |' for r in rows]
    # Replanning time per fifth of the flight, and the slope of a least-squares line.
    slope = float('nan')
    if len(calls) >= 10:
        lines += ['', '| part of the flight | planning calls | median [ms] | p95 [ms] |', '|---|---|---|---|']
        t_end = max(c[0] for c in calls)
        for k in range(5):
            part = [c[1] for c in calls if k * t_end / 5 <= c[0] < (k + 1) * t_end / 5 or (k == 4 and c[0] == t_end)]
            if part:
                lines.append(f'| {k + 1}/5 | {len(part)} | {statistics.median(part):.2f} | {pct(part, 0.95):.2f} |')
        ts, ms = [c[0] / 3600.0 for c in calls], [c[1] for c in calls]
        mt, mm = statistics.mean(ts), statistics.mean(ms)
        var = sum((t - mt) ** 2 for t in ts)
        slope = sum((t - mt) * (m - mm) for t, m in zip(ts, ms)) / var if var > 0 else float('nan')
    result = (f'RESULT sim_minutes={sim / 60:.1f} goals={n_goals_done} collisions={collisions} '
              f'rss_growth_mb_max={growth_max:.2f} planner_cpu_mean={planner_cpu:.1f} '
              f'replan_ms_slope_per_hour={slope:.2f}')
    lines += ['', '```', result, '```', '']
    with open(os.path.join(args.out, 'soak.md'), 'w') as f:
        f.write('\n'.join(lines))
    print('\n'.join(lines[:-3]))
    print(result)
    return 0 if collisions == 0 and not ended_early else 1


if __name__ == '__main__':
    sys.exit(main(sys.argv))
