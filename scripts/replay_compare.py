#!/usr/bin/env python3
"""Compares a recorded flight with its replay (scripts/check_replay.sh): the map and the plans.

  replay_compare.py FLIGHT_MAP_BAG FLIGHT_BAG REPLAY_BAG

FLIGHT_MAP_BAG holds the flight's /planner/mapping/occupancy (recorded beside it by the check),
FLIGHT_BAG is the bag planner.launch's record:=true wrote, REPLAY_BAG the replayed planner's
occupancy, global route, reference and replan events. Prints one line per case,
`<case> pass|fail: <why>`, and exits non-zero if any fails:
  map    the last occupancy of each: the same voxels (Jaccard index >= 0.9 of 0.1 m voxels)
  route  the first global route of each: the same way (lengths within 5 %, every point of one
         within 0.5 m of the other)
  plans  the replayed planner published trajectories (replan events with a trajectory)
Run with /usr/bin/python3 (ROS's rosbag and sensor_msgs modules).
"""
import math
import sys

import rosbag
from sensor_msgs import point_cloud2

OCCUPANCY = '/planner/mapping/occupancy'
ROUTE = '/planning/global_route'
EVENTS = '/planning/replan_event'
VOXEL_M = 0.1


def messages(path, topic):
    with rosbag.Bag(path) as bag:
        return [msg for _, msg, _ in bag.read_messages(topics=[topic])]


def voxels(cloud):
    return {tuple(int(math.floor(c / VOXEL_M)) for c in p[:3])
            for p in point_cloud2.read_points(cloud, field_names=('x', 'y', 'z'), skip_nans=True)}


def path_points(path_msg):
    return [(p.pose.position.x, p.pose.position.y, p.pose.position.z) for p in path_msg.poses]


def length(points):
    return sum(math.dist(a, b) for a, b in zip(points, points[1:]))


def resample(points, step=0.05):
    out = [points[0]]
    for a, b in zip(points, points[1:]):
        n = max(1, int(math.ceil(math.dist(a, b) / step)))
        out += [tuple(a[i] + (b[i] - a[i]) * k / n for i in range(3)) for k in range(1, n + 1)]
    return out


def farthest(a, b):
    """The largest distance from a point of polyline a to polyline b (both resampled)."""
    fa, fb = resample(a), resample(b)
    return max(min(math.dist(p, q) for q in fb) for p in fa)


def compare(flight_map_bag, flight_bag, replay_bag):
    results = []
    flight_maps, replay_maps = messages(flight_map_bag, OCCUPANCY), messages(replay_bag, OCCUPANCY)
    if not flight_maps or not replay_maps:
        results.append(('map', False, f'occupancy messages: flight {len(flight_maps)}, replay {len(replay_maps)}'))
    else:
        a, b = voxels(flight_maps[-1]), voxels(replay_maps[-1])
        jaccard = len(a & b) / max(1, len(a | b))
        ok = jaccard >= 0.9 and len(a) >= 100
        results.append(('map', ok, f'{len(a)} occupied voxels in flight, {len(b)} in replay, Jaccard index {jaccard:.3f}'))
    flight_routes, replay_routes = messages(flight_bag, ROUTE), messages(replay_bag, ROUTE)
    flight_routes = [r for r in flight_routes if len(r.poses) >= 2]
    replay_routes = [r for r in replay_routes if len(r.poses) >= 2]
    if not flight_routes or not replay_routes:
        results.append(('route', False, f'global routes: flight {len(flight_routes)}, replay {len(replay_routes)}'))
    else:
        a, b = path_points(flight_routes[0]), path_points(replay_routes[0])
        la, lb = length(a), length(b)
        apart = max(farthest(a, b), farthest(b, a))
        ok = abs(la - lb) <= 0.05 * max(la, lb) and apart <= 0.5
        results.append(('route', ok, f'first route {la:.2f} m in flight, {lb:.2f} m in replay, at most {apart:.2f} m apart'))
    events = messages(replay_bag, EVENTS)
    published = sum(1 for e in events if e.trajectory_id >= 0)
    flight_published = sum(1 for e in messages(flight_bag, EVENTS) if e.trajectory_id >= 0)
    results.append(('plans', published >= 1,
                    f'the replay published {published} trajectories in {len(events)} planning calls '
                    f'(the flight {flight_published})'))
    return results


def main(argv):
    if len(argv) != 4:
        print(__doc__, file=sys.stderr)
        return 2
    results = compare(*argv[1:])
    for name, ok, why in results:
        print(f'{name} {"pass" if ok else "fail"}: {why}')
    return 0 if all(ok for _, ok, _ in results) else 1


if __name__ == '__main__':
    sys.exit(main(sys.argv))
