"""rospy vs SGM's bridge on the same 20 000-point Velodyne cloud (x y z intensity ring time,
22-byte little-endian points; the same points as bridge/benches/bridge.rs builds).

Measured in one run: `cargo bench -p sgm-bridge --bench bridge` (criterion median of
`cloud_in_20k/velodyne`: rosrust decode + `Inputs::cloud`), then here, in Debian's Python with
its ROS 1 message packages, the same work the rospy way: `PointCloud2.deserialize` and
`sensor_msgs.point_cloud2.read_points(field_names=("x", "y", "z"), skip_nans=True)` into a list
(median of 15). The points read back are checked against the ones built.
Usage: compare_rospy.py CRITERION_DIR
"""
import io
import json
import math
import statistics
import struct
import sys
import time
from pathlib import Path

from sensor_msgs import point_cloud2
from sensor_msgs.msg import PointCloud2, PointField

POINTS = 20_000


def scan_points():
    """bridge/benches/bridge.rs `scan_points`, in float32."""
    out = []
    for k in range(POINTS):
        ring, step = float(k % 16), float(k // 16)
        azimuth, elevation = step * 2 * math.pi / 1250.0, math.radians(ring - 7.5) * 2.0
        r = 5.0 + (k % 97) * 0.3
        xyz = (r * math.cos(elevation) * math.cos(azimuth), r * math.cos(elevation) * math.sin(azimuth),
               r * math.sin(elevation))
        out.append(struct.unpack("<3f", struct.pack("<3f", *xyz)))
    return out


def velodyne_cloud(points):
    fields = [PointField(name, offset, dt, 1) for name, offset, dt in
              [("x", 0, 7), ("y", 4, 7), ("z", 8, 7), ("intensity", 12, 7), ("ring", 16, 4), ("time", 18, 7)]]
    data = b"".join(struct.pack("<ffffHf", *p, 40.0, k % 16, k * 5e-6) for k, p in enumerate(points))
    msg = PointCloud2(height=1, width=POINTS, fields=fields, is_bigendian=False, point_step=22,
                      row_step=22 * POINTS, data=data, is_dense=True)
    msg.header.frame_id = "alpha/base_link"
    buf = io.BytesIO()
    msg.serialize(buf)
    return buf.getvalue()


def rospy_read(body):
    msg = PointCloud2().deserialize(body)
    return list(point_cloud2.read_points(msg, field_names=("x", "y", "z"), skip_nans=True))


def median_ms(f, reps=15):
    times = []
    for _ in range(reps):
        t = time.perf_counter()
        f()
        times.append(time.perf_counter() - t)
    return statistics.median(times) * 1e3


def main():
    criterion = Path(sys.argv[1])
    points = scan_points()
    body = velodyne_cloud(points)
    read = rospy_read(body)
    assert len(read) == POINTS and all(a == b for a, b in zip(read, points)), "rospy reads back what was built"
    rospy_ms = median_ms(lambda: rospy_read(body))
    rows = []
    for bench in ["cloud_in_20k/velodyne", "cloud_in_20k/sgm_labelled", "frame_in_20k/odometry_image_cloud"]:
        estimates = json.loads((criterion / bench / "new" / "estimates.json").read_text())
        rows.append((bench, estimates["median"]["point_estimate"] * 1e-6))
    print(f"20 000-point cloud, {len(body) / 1e6:.2f} MB: decode and read x y z")
    print(f"  rospy (deserialize + point_cloud2.read_points)   {rospy_ms:8.2f} ms")
    for bench, ms in rows:
        print(f"  sgm bridge {bench:38s}{ms:8.3f} ms")
    print(f"  ratio rospy / sgm (velodyne cloud)               {rospy_ms / rows[0][1]:8.0f} x")


main()
