#!/usr/bin/python3
"""Rostest node of the closed-loop fault-injection tests (plan_manage/test/fault_*.test).

The launch file flies a short mission in simulated time (simulation.launch with the flight monitor)
with faults injected by the simulator (config/quadrotor.yaml faults/*). This node optionally kills
the planner node mid-flight (rosnode's API; the launch file respawns it), waits for the monitor's
latched report (/flight_monitor/report: the report JSON with the setpoint figures and the faults
seen), and checks what the house style's flight-safety rules ask of every failure:
  - no collision, and the minimum clearance above min_clearance_m (the body radius plus a margin);
  - the worst commanded deceleration within max_brake_acc_mps2 + decel_margin_mps2;
  - no setpoint jump (a step over |v| dt + 5 cm; a re-anchoring after an odometry jump is not one);
  - each fault in expect_faults injected during the flight (the machinery did its part);
  - for each kind in expect_stopped_at_end: the commanded speed when that fault ended below
    stop_speed_mps (the vehicle was brought to a hover while it lasted);
  - the recovery: every goal reached (expect_completed) and the restarts / time steps the monitor
    must have seen (min_planner_restarts, min_time_steps).
Wall-clock limits are hang guards only (wall_timeout_s); the flight itself runs on the simulator's
clock in lockstep with the controller.

Parameters (private): wall_timeout_s 400, kill_planner_at_speed_mps 0 (0 = never), planner_node
/planner, max_brake_acc_mps2 5.0, decel_margin_mps2 1.0, max_setpoint_jumps 0, min_clearance_m 0.2,
expect_completed true, expect_faults [] (kinds), expect_stopped_at_end [] (kinds), stop_speed_mps 0.25,
min_planner_restarts 0, min_time_steps 0.
"""
import json
import math
import struct
import sys
import threading
import time
import unittest

import rosnode
import rospy
import rostest
from std_msgs.msg import String

NAME = 'fault_test'


def odometry_position_speed(buf):
    """(x, y, z), |v| of a serialised nav_msgs/Odometry. Debian's ROS ships no Python nav_msgs, so
    the message is read as rospy.AnyMsg: Header (seq, stamp, frame_id), child_frame_id, pose (7
    float64) and its covariance (36), then the twist's linear velocity (3 float64)."""
    def skip_string(offset):
        (n,) = struct.unpack_from('<I', buf, offset)
        return offset + 4 + n
    o = skip_string(12)  # seq, stamp.sec, stamp.nsec, frame_id
    o = skip_string(o)   # child_frame_id
    x, y, z = struct.unpack_from('<3d', buf, o)
    vx, vy, vz = struct.unpack_from('<3d', buf, o + 8 * (7 + 36))
    return (x, y, z), math.sqrt(vx * vx + vy * vy + vz * vz)


def fmt(x, d=2):
    return 'n/a' if x is None or (isinstance(x, float) and math.isnan(x)) else f'{x:.{d}f}'


class FaultFlight(unittest.TestCase):
    def setUp(self):
        self.lock = threading.Lock()
        self.report = None
        self.killed = False
        self.kill_speed = float(rospy.get_param('~kill_planner_at_speed_mps', 0.0))
        self.planner_node = rospy.get_param('~planner_node', '/planner')
        self.report_sub = rospy.Subscriber('/flight_monitor/report', String, self.on_report, queue_size=1)
        if self.kill_speed > 0.0:
            self.odom_sub = rospy.Subscriber('/odom', rospy.AnyMsg, self.on_odom, queue_size=1)

    def on_report(self, msg):
        with self.lock:
            self.report = json.loads(msg.data)

    def on_odom(self, msg):
        if self.killed:
            return
        p, speed = odometry_position_speed(msg._buff)
        if speed < self.kill_speed:
            return
        self.killed = True  # once; the launch file respawns the node
        rospy.logwarn(f'{NAME}: killing {self.planner_node} at ({p[0]:.2f} {p[1]:.2f} {p[2]:.2f}), {speed:.2f} m/s')
        threading.Thread(target=rosnode.kill_nodes, args=([self.planner_node],), daemon=True).start()

    def test_fault_flight(self):
        wall_timeout = float(rospy.get_param('~wall_timeout_s', 400.0))
        deadline = time.monotonic() + wall_timeout
        while not rospy.is_shutdown() and time.monotonic() < deadline:
            with self.lock:
                if self.report is not None:
                    break
            time.sleep(0.2)  # wall time: the simulated clock may step backwards
        with self.lock:
            r = self.report
        self.assertIsNotNone(r, f'no /flight_monitor/report within {wall_timeout:.0f} s of wall time')

        max_brake = float(rospy.get_param('~max_brake_acc_mps2', 5.0))
        decel_margin = float(rospy.get_param('~decel_margin_mps2', 1.0))
        max_jumps = int(rospy.get_param('~max_setpoint_jumps', 0))
        min_clearance = float(rospy.get_param('~min_clearance_m', 0.2))
        expect_completed = bool(rospy.get_param('~expect_completed', True))
        expect_faults = list(rospy.get_param('~expect_faults', []))
        expect_stopped = list(rospy.get_param('~expect_stopped_at_end', []))
        stop_speed = float(rospy.get_param('~stop_speed_mps', 0.25))
        min_restarts = int(rospy.get_param('~min_planner_restarts', 0))
        min_time_steps = int(rospy.get_param('~min_time_steps', 0))

        faults = r.get('faults', [])
        in_flight = [f for f in faults if f['goal_index'] >= 0]
        ends = {}
        for f in in_flight:
            if f['phase'] == 'end':
                ends.setdefault(f['kind'], f)
        line = (f"{NAME}: {r['name']}: {r['status']}: {r['goals_reached']}/{r['goals_total']} goals, "
                f"{r['collisions']} collisions, min clearance {fmt(r['min_clearance_m'])} m, worst decel "
                f"{fmt(r['max_decel_mps2'])} m/s^2 (limit {max_brake:.1f} + {decel_margin:.1f}), worst acc "
                f"{fmt(r['max_acc_mps2'])} m/s^2, {r['setpoint_jumps']} setpoint jumps, {r['reanchorings']} "
                f"re-anchorings, {r['faults_injected']} faults, {r['planner_restarts']} planner restarts, "
                f"{r['goal_resends']} goals re-sent, {r['time_steps']} time steps, speed mean/max "
                f"{fmt(r['mean_speed_mps'])}/{fmt(r['max_speed_mps'])} m/s, {fmt(r['duration_s'], 1)} s; "
                + '; '.join(f"{f['kind']} {f['phase']} at {fmt(f['t_s'], 1)} s (commanded "
                            f"{fmt(f['commanded_speed_mps'])} m/s, true {fmt(f['true_speed_mps'])} m/s)"
                            for f in faults))
        print(line)
        rospy.loginfo(line)
        steps = r.get('setpoint_steps', [])
        for s in steps:
            print(f"{NAME}: setpoint step at {fmt(s['t_s'], 2)} s: {fmt(s['step_m'], 3)} m (allowed "
                  f"{fmt(s['allowed_m'], 3)} m){' re-anchoring' if s['reanchoring'] else ' JUMP'}")

        failures = []

        def check(ok, what):
            if not ok:
                failures.append(what)

        # No collision, clearance kept.
        check(r['collisions'] == 0, f"{r['collisions']} collisions ({r['message']})")
        check((r['min_clearance_m'] or 0.0) > min_clearance,
              f"minimum clearance {fmt(r['min_clearance_m'])} m <= {min_clearance} m")
        # Deceleration within the limit plus the margin.
        check(r['max_decel_mps2'] <= max_brake + decel_margin,
              f"worst commanded deceleration {fmt(r['max_decel_mps2'])} m/s^2 at {fmt(r.get('max_decel_t_s'), 2)} s "
              f"(from the {r.get('max_decel_from', '?').replace('_', ' ')}) "
              f"> {max_brake} + {decel_margin} m/s^2")
        # No setpoint jump.
        check(r['setpoint_jumps'] <= max_jumps,
              f"{r['setpoint_jumps']} setpoint jumps: {[s for s in steps if not s['reanchoring']][:5]}")
        # The faults were injected while flying.
        for kind in expect_faults:
            check(any(f['kind'] == kind and f['phase'] in ('start', 'step') for f in in_flight),
                  f'{kind} was not injected during the flight')
        # Stopped while the fault lasted.
        for kind in expect_stopped:
            if kind not in ends:
                check(False, f'{kind} did not end during the flight')
            else:
                v = ends[kind]['commanded_speed_mps']
                check(v is not None and v <= stop_speed,
                      f'commanded speed {fmt(v)} m/s when {kind} ended > {stop_speed} m/s (no stop)')
        # Recovery.
        if self.kill_speed > 0.0:
            check(self.killed, 'the planner was never killed (the vehicle never reached the speed)')
        check(r['planner_restarts'] >= min_restarts,
              f"{r['planner_restarts']} planner restarts seen by the monitor < {min_restarts}")
        check(r['time_steps'] >= min_time_steps, f"{r['time_steps']} ROS time steps seen by the monitor < {min_time_steps}")
        if expect_completed:
            check(r['goals_reached'] == r['goals_total'],
                  f"mission not completed: {r['goals_reached']}/{r['goals_total']} goals ({r['message']})")
        self.assertEqual(failures, [], '; '.join(failures))

if __name__ == '__main__':
    rospy.init_node(NAME, disable_signals=True)
    rostest.rosrun('topo_planner', NAME, FaultFlight, sys.argv)
