#!/usr/bin/python3
"""Rostest node of plan_manage/test/planner_inputs.test: the planner node's input checks, fault by fault.

Publishes odometry (nav_msgs/Odometry on /odom) and depth images (32FC1 on /depth, the camera pose
from the odometry) and reads the planner's heartbeat (/planning/heartbeat: input freshness as the FSM
sees it). In order:
  1. odometry in a frame other than the planner's frame_id is ignored: no odometry, inputs not ok;
  2. odometry in the right frame: fresh;
  3. depth images without a single valid pixel (open sky: every return NaN) still prove the camera
     alive: depth fresh, inputs ok;
  4. the camera stops: depth goes stale within depth_timeout_s (+ margins), inputs not ok, and
     waypoints sent meanwhile are refused (the FSM stays in WAIT_TARGET);
  5. the camera comes back: inputs ok again.
Wall time; the timeouts are hang guards (the planner's rules are checked on the heartbeat's ages).
"""
import struct
import threading
import time
import unittest

import rospy
import rostest
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry, Path
from sensor_msgs.msg import Image

from topo_planner.msg import PlannerHeartbeat

NAME = 'planner_inputs_test'
WIDTH, HEIGHT = 64, 48
NAN_IMAGE = struct.pack('<f', float('nan')) * (WIDTH * HEIGHT)


class PlannerInputsTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node(NAME)
        cls.lock = threading.Lock()
        cls.heartbeats = []
        cls.odom_frame = 'map'
        cls.send_odom = True
        cls.send_depth = False
        cls.odom_pub = rospy.Publisher('/odom', Odometry, queue_size=10)
        cls.depth_pub = rospy.Publisher('/depth', Image, queue_size=10)
        cls.waypoints_pub = rospy.Publisher('/planning/waypoints', Path, queue_size=1, latch=True)
        rospy.Subscriber('/planning/heartbeat', PlannerHeartbeat, cls.on_heartbeat)
        cls.stop = False
        cls.thread = threading.Thread(target=cls.publish_loop, daemon=True)
        cls.thread.start()

    @classmethod
    def tearDownClass(cls):
        cls.stop = True
        cls.thread.join(2.0)

    @classmethod
    def on_heartbeat(cls, msg):
        with cls.lock:
            cls.heartbeats.append(msg)

    @classmethod
    def publish_loop(cls):
        k = 0
        while not cls.stop and not rospy.is_shutdown():
            stamp = rospy.Time.now()
            if cls.send_odom:
                o = Odometry()
                o.header.stamp = stamp
                o.header.frame_id = cls.odom_frame
                o.child_frame_id = 'body'
                o.pose.pose.position.z = 1.0
                o.pose.pose.orientation.w = 1.0
                cls.odom_pub.publish(o)
            if cls.send_depth and k % 3 == 0:  # ~17 Hz, stamped like the odometry (exact sync)
                img = Image()
                img.header.stamp = stamp
                img.header.frame_id = 'camera'
                img.width, img.height = WIDTH, HEIGHT
                img.encoding = '32FC1'
                img.is_bigendian = 0
                img.step = 4 * WIDTH
                img.data = NAN_IMAGE
                cls.depth_pub.publish(img)
            k += 1
            time.sleep(0.02)

    def last_heartbeat_after(self, t, timeout_s=10.0):
        """The first heartbeat sent at least 0.3 s after wall time t (the inputs of the moment)."""
        deadline = time.time() + timeout_s
        while time.time() < deadline:
            with self.lock:
                for hb in self.heartbeats:
                    if hb.header.stamp.to_sec() >= t + 0.3:
                        return hb
            time.sleep(0.05)
        self.fail('no planner heartbeat within %.0f s' % timeout_s)

    def wait_for(self, predicate, what, timeout_s=10.0):
        deadline = time.time() + timeout_s
        hb = None
        while time.time() < deadline:
            with self.lock:
                hb = self.heartbeats[-1] if self.heartbeats else None
            if hb is not None and predicate(hb):
                return hb
            time.sleep(0.05)
        self.fail('%s: not seen within %.0f s (last heartbeat: %s)' % (what, timeout_s, hb))

    def test_inputs_in_order(self):
        # 1. Odometry in frame 'map' (the planner's frame is 'world'): ignored.
        self.last_heartbeat_after(rospy.Time.now().to_sec() + 1.0, timeout_s=30.0)
        hb = self.last_heartbeat_after(rospy.Time.now().to_sec())
        self.assertFalse(hb.inputs_ok)
        self.assertEqual(hb.odom_age_s, -1.0, 'odometry in the wrong frame was used')
        self.assertIn('odometry', hb.inputs_status)

        # 2. The right frame: fresh odometry (depth still missing).
        self.__class__.odom_frame = 'world'
        hb = self.wait_for(lambda h: 0.0 <= h.odom_age_s <= 0.25, 'fresh odometry')
        self.assertFalse(hb.inputs_ok)
        self.assertIn('depth', hb.inputs_status)

        # 3. Depth without a valid pixel is a live camera.
        self.__class__.send_depth = True
        hb = self.wait_for(lambda h: h.inputs_ok, 'inputs ok with all-NaN depth images')
        self.assertTrue(0.0 <= hb.depth_age_s <= 0.5, hb.depth_age_s)

        # 4. The camera stops: stale within depth_timeout_s (0.5 s) plus the heartbeat period.
        self.__class__.send_depth = False
        t_stop = rospy.Time.now().to_sec()
        hb = self.wait_for(lambda h: not h.inputs_ok, 'depth stale after the camera stopped')
        self.assertIn('depth', hb.inputs_status)
        self.assertLess(hb.header.stamp.to_sec() - t_stop, 0.5 + 0.5)
        path = Path()
        path.header.frame_id = 'world'
        path.header.stamp = rospy.Time.now()
        goal = PoseStamped()
        goal.header = path.header
        goal.pose.position.x, goal.pose.position.z = 5.0, 1.0
        goal.pose.orientation.w = 1.0
        path.poses.append(goal)
        self.waypoints_pub.publish(path)
        t_goal = rospy.Time.now().to_sec()
        hb = self.last_heartbeat_after(t_goal + 0.5)
        self.assertEqual(hb.fsm_state, 'WAIT_TARGET', 'waypoints accepted while depth was stale')

        # 5. The camera is back: inputs ok again.
        self.__class__.send_depth = True
        self.wait_for(lambda h: h.inputs_ok, 'inputs ok after the camera came back')


if __name__ == '__main__':
    rostest.rosrun('topo_planner', NAME, PlannerInputsTest)
