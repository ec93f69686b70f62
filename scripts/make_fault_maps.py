#!/usr/bin/python3
"""Writes the purpose-made maps of the fault-injection tests (plan_manage/test/fault_*.test) as ASCII
PCD files of occupied voxel centres (0.1 m voxels; map_generator's map_file:= loads them):

  corner_pillar.pcd   a 4 m high wall along x (x in [-16, 1.5], y in [1.0, 1.2]), 1 m to the left of a
                      flight from (-12, 0, 1) east to the waypoint (3, 0, 1) just past the wall's end,
                      then around the corner north to (3, 10, 1); a pillar (radius 0.3 m) at (3, 3)
                      stands on that second leg, 2.3 m behind the corner, where the wall hides it from
                      the approach (and the camera, looking along the approach, could not see it anyway).
                      Both reach above the planner's map ceiling (3.7 m in simulation.launch), so
                      nothing goes over them.

  python3 scripts/make_fault_maps.py [OUT_DIR]   (default: plan_manage/test/data)
"""
import math
import os
import sys

RES = 0.1


def centres(lo, hi):
    """Voxel centres (k + 0.5) * RES of the voxels whose centre lies in [lo, hi]."""
    k0, k1 = math.ceil(lo / RES - 0.5), math.floor(hi / RES - 0.5)
    return [round((k + 0.5) * RES, 3) for k in range(k0, k1 + 1)]


def box(x0, x1, y0, y1, z0, z1):
    return {(x, y, z) for x in centres(x0, x1) for y in centres(y0, y1) for z in centres(z0, z1)}


def cylinder(cx, cy, r, z0, z1):
    return {(x, y, z) for x in centres(cx - r, cx + r) for y in centres(cy - r, cy + r)
            if (x - cx) ** 2 + (y - cy) ** 2 <= r * r for z in centres(z0, z1)}


def write_pcd(path, points):
    points = sorted(points)
    with open(path, 'w') as f:
        f.write('# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\n'
                f'COUNT 1 1 1\nWIDTH {len(points)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(points)}\n'
                'DATA ascii\n')
        for p in points:
            f.write(f'{p[0]:.2f} {p[1]:.2f} {p[2]:.2f}\n')
    print(f'make_fault_maps: {path}: {len(points)} voxels')


def main(argv):
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    out = argv[1] if len(argv) > 1 else os.path.join(root, 'plan_manage', 'test', 'data')
    os.makedirs(out, exist_ok=True)
    corner = box(-16.0, 1.5, 1.0, 1.2, 0.0, 4.0) | cylinder(3.0, 3.0, 0.3, 0.0, 4.0)
    write_pcd(os.path.join(out, 'corner_pillar.pcd'), corner)
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv))
