#!/usr/bin/python3
"""Rostest node of simulator_faults.test: the simulator's injected faults, seen on its topics.

Schedule (simulated seconds from the clock start; ROS time = 1 + t until the clock step):
depth blackout [3, 4), odometry blackout [5, 6), odometry jump by (1, -0.5, 0) m at 7, clock step of
-3 s at 8. The vehicle hovers at (0, 0, 1) with no position command. Checked:
  - no depth image stamped inside the blackout, images before and after it;
  - no odometry stamped inside the odometry blackout while the ground truth goes on, and the vehicle
    (held by the simulator's failsafe while the controller, without odometry, is silent) stays put
    until the jump;
  - after the jump, odometry = ground truth + the offset, and ~odom_offset says so;
  - /clock goes back by 3 s once, and the stamps after it follow;
  - one fault event line per change, kind and phase first.
Messages are read as rospy.AnyMsg (Debian's ROS has no Python nav_msgs / sensor_msgs): only the
header stamp and the odometry position are needed. Waits are bounded in wall time (hang guards).
"""
import math
import os
import struct
import sys
import threading
import time
import unittest

import rospy
import rostest
from rosgraph_msgs.msg import Clock
from std_msgs.msg import String

NAME = 'simulator_faults_test'


def stamp_of(buf):
    secs, nsecs = struct.unpack_from('<II', buf, 4)
    return secs + 1e-9 * nsecs


def odom_position(buf):
    (n,) = struct.unpack_from('<I', buf, 12)
    o = 16 + n
    (n,) = struct.unpack_from('<I', buf, o)
    return struct.unpack_from('<3d', buf, o + 4 + n)


class SimulatorFaults(unittest.TestCase):
    def setUp(self):
        self.lock = threading.Lock()
        self.odom, self.truth, self.images, self.clock, self.events, self.offsets = [], [], [], [], [], []
        sub = rospy.Subscriber
        self.subs = [
            sub('/odom', rospy.AnyMsg, lambda m: self.add(self.odom, (stamp_of(m._buff), odom_position(m._buff)))),
            sub('/quadrotor_sim/ground_truth', rospy.AnyMsg,
                lambda m: self.add(self.truth, (stamp_of(m._buff), odom_position(m._buff))), queue_size=1000),
            sub('/camera/depth/image_rect_raw', rospy.AnyMsg, lambda m: self.add(self.images, stamp_of(m._buff))),
            sub('/clock', Clock, lambda m: self.add(self.clock, m.clock.to_sec()), queue_size=1000),
            sub('/quadrotor_sim/fault_event', String, lambda m: self.add(self.events, m.data), queue_size=50),
            sub('/quadrotor_sim/odom_offset', rospy.AnyMsg, lambda m: self.add(self.offsets, m._buff)),
        ]

    def add(self, into, item):
        with self.lock:
            into.append(item)

    def test_faults(self):
        # Until the clock has stepped back and run 1.5 s on (ROS time 5 + 1.5), at most 90 s of wall time.
        # (stretched under the sanitizers: make test-asan / test-tsan)
        deadline = time.monotonic() + 90.0 * max(1.0, float(os.environ.get('TOPO_PLANNER_TIME_LIMIT_SCALE', '1')))
        while time.monotonic() < deadline and not rospy.is_shutdown():
            with self.lock:
                stepped = any(b < a - 1.0 for a, b in zip(self.clock, self.clock[1:]))
                if stepped and self.clock[-1] > 6.5:
                    break
            time.sleep(0.1)
        with self.lock:
            odom, truth, images = list(self.odom), list(self.truth), list(self.images)
            clock, events, offsets = list(self.clock), list(self.events), list(self.offsets)
        self.assertTrue(clock, 'no /clock')
        # Before the step: ROS time = 1 + t. Keep what came before the step for the blackout checks.
        step_at = next((i for i, (a, b) in enumerate(zip(clock, clock[1:])) if b < a - 1.0), None)
        self.assertIsNotNone(step_at, f'/clock never went back (last {clock[-1]:.3f})')
        # 1 kHz /clock from 9.0 back to 6.0. A subscriber may miss some around the step (under TSan the
        # last one seen before it was 8.971), which can only lower the last time seen before and raise
        # the first after: each is checked from its own side.
        self.assertLessEqual(clock[step_at], 9.0 + 0.002)
        self.assertGreater(clock[step_at], 9.0 - 0.1)
        self.assertGreaterEqual(clock[step_at + 1], 6.0 - 0.002)
        self.assertLess(clock[step_at + 1], 6.0 + 0.1)

        def before_step(seq, key=lambda x: x):
            out = []
            for x in seq:  # in arrival order: cut at the first stamp that went back
                if out and key(x) < key(out[-1]) - 1.0:
                    break
                out.append(x)
            return out

        img = before_step(images)
        self.assertTrue(any(3.0 < s < 4.0 for s in img), 'no image before the depth blackout')
        self.assertFalse([s for s in img if 4.0 + 0.034 <= s < 5.0], 'images inside the depth blackout [4, 5)')
        self.assertTrue(any(5.0 < s < 5.5 for s in img), 'no image after the depth blackout')

        od = before_step(odom, key=lambda x: x[0])
        tr = before_step(truth, key=lambda x: x[0])
        self.assertFalse([s for s, _ in od if 6.0 <= s < 7.0 - 1e-6], 'odometry inside the odometry blackout [6, 7)')
        self.assertTrue(any(6.0 < s < 7.0 for s, _ in tr), 'no ground truth during the odometry blackout')
        self.assertTrue(any(7.0 <= s < 7.5 for s, _ in od), 'no odometry after the odometry blackout')
        # Hovering until the jump (after it the controller, fed the offset odometry, moves the body by
        # minus the offset), also while the failsafe held the vehicle in the odometry blackout.
        drift = max(math.dist(p, (0.0, 0.0, 1.0)) for s, p in tr if s < 8.0)
        self.assertLess(drift, 0.3, 'the vehicle left its hover')

        # The jump at ROS time 8: odometry = truth + (1, -0.5, 0) after it, = truth before.
        truth_at = {round(s, 3): p for s, p in tr}
        diffs_before = [tuple(a - b for a, b in zip(p, truth_at[round(s, 3)])) for s, p in od
                        if 7.0 < s < 8.0 - 1e-6 and round(s, 3) in truth_at]
        diffs_after = [tuple(a - b for a, b in zip(p, truth_at[round(s, 3)])) for s, p in od
                       if 8.0 <= s < 9.0 and round(s, 3) in truth_at]
        self.assertTrue(diffs_before and diffs_after, 'odometry and truth of the same stamps around the jump')
        for d in diffs_before:
            self.assertLess(math.dist(d, (0.0, 0.0, 0.0)), 1e-6)
        for d in diffs_after:
            self.assertLess(math.dist(d, (1.0, -0.5, 0.0)), 1e-6)
        last_offset = struct.unpack_from('<3d', offsets[-1], len(offsets[-1]) - 24)
        self.assertLess(math.dist(last_offset, (1.0, -0.5, 0.0)), 1e-9)

        # Stamps after the step follow the clock: odometry stamped 6..6.5 after stamps near 9.
        self.assertTrue(any(6.0 < s < 6.5 for s, _ in odom[len(od):]), 'no odometry stamped after the clock step')

        kinds = [tuple(e.split()[:2]) for e in events]
        self.assertEqual(kinds, [('depth_blackout', 'start'), ('depth_blackout', 'end'), ('odom_blackout', 'start'),
                                 ('odom_blackout', 'end'), ('odom_jump', 'step'), ('clock_step', 'step')], events)


if __name__ == '__main__':
    rospy.init_node(NAME, disable_signals=True)
    rostest.rosrun('topo_planner', NAME, SimulatorFaults, sys.argv)
