"""`match` straight from a robot's bag, written by another tool: the real
3DTK scans in data/3dtk_dat become a rosbag2 written by rosbags 0.11.9 —
each scan a sensor_msgs/msg/PointCloud2 (x, y, z float32 and an
intensity, in frame base_link), its .pose an odometry message
(nav_msgs/msg/Odometry odom → base_link) and a /tf (map → odom, static) —
and `match` must register the bag (poses from --odom, and from /tf) as it
registers the 3DTK directory itself; the bag `match --ros2-bag` writes is
read back by rosbags and mcap-ros2-support against poses.json.

    python check_ros2_match.py CPS_SURVEY REPO WORKDIR
"""

import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore


def fail(msg):
    print(f"check_ros2_match: {msg}", file=sys.stderr)
    sys.exit(1)


# 3DTK axes (x right, y up, z forward, cm) → ours (x forward, y left, z up, m).
C = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def rot(axis, a):
    c, s = math.cos(a), math.sin(a)
    return {
        "x": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
        "y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
        "z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]),
    }[axis]


def pose_of(path):
    rows = [list(map(float, l.split())) for l in path.read_text().splitlines() if l.strip()]
    t, (ax, ay, az) = np.array(rows[0]) / 100.0, [math.radians(a) for a in rows[1]]
    r = rot("x", ax) @ rot("y", ay) @ rot("z", az)
    return C @ r @ C.T, C @ t


def quaternion(r):
    w = math.sqrt(max(0.0, 1 + r[0, 0] + r[1, 1] + r[2, 2])) / 2
    x = math.copysign(math.sqrt(max(0.0, 1 + r[0, 0] - r[1, 1] - r[2, 2])) / 2, r[2, 1] - r[1, 2])
    y = math.copysign(math.sqrt(max(0.0, 1 - r[0, 0] + r[1, 1] - r[2, 2])) / 2, r[0, 2] - r[2, 0])
    z = math.copysign(math.sqrt(max(0.0, 1 - r[0, 0] - r[1, 1] + r[2, 2])) / 2, r[1, 0] - r[0, 1])
    return x, y, z, w


def write_bag(data, bag):
    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    Header, Time = T["std_msgs/msg/Header"], T["builtin_interfaces/msg/Time"]
    Point, Quat, Pose = T["geometry_msgs/msg/Point"], T["geometry_msgs/msg/Quaternion"], T["geometry_msgs/msg/Pose"]
    PoseCov, Twist, TwistCov = (
        T["geometry_msgs/msg/PoseWithCovariance"],
        T["geometry_msgs/msg/Twist"],
        T["geometry_msgs/msg/TwistWithCovariance"],
    )
    Vector3, Odometry = T["geometry_msgs/msg/Vector3"], T["nav_msgs/msg/Odometry"]
    Transform, TransformStamped, TFMessage = (
        T["geometry_msgs/msg/Transform"],
        T["geometry_msgs/msg/TransformStamped"],
        T["tf2_msgs/msg/TFMessage"],
    )
    PointCloud2, PointField = T["sensor_msgs/msg/PointCloud2"], T["sensor_msgs/msg/PointField"]
    scans = sorted(data.glob("scan*.3d"))
    with Writer(bag, version=8, storage_plugin=StoragePlugin.MCAP) as w:
        points_c = w.add_connection("/points", PointCloud2.__msgtype__, typestore=ts)
        odom_c = w.add_connection("/odom", Odometry.__msgtype__, typestore=ts)
        tf_c = w.add_connection("/tf", TFMessage.__msgtype__, typestore=ts)
        static_c = w.add_connection("/tf_static", TFMessage.__msgtype__, typestore=ts)
        t0 = 1_700_000_000 * 10**9
        identity = Transform(translation=Vector3(x=0.0, y=0.0, z=0.0), rotation=Quat(x=0.0, y=0.0, z=0.0, w=1.0))
        stamp0 = Time(sec=t0 // 10**9, nanosec=0)
        w.write(
            static_c,
            t0,
            ts.serialize_cdr(
                TFMessage(
                    transforms=[
                        TransformStamped(header=Header(stamp=stamp0, frame_id="map"), child_frame_id="odom", transform=identity)
                    ]
                ),
                TFMessage.__msgtype__,
            ),
        )
        for k, scan in enumerate(scans):
            ns = t0 + k * 10**9
            stamp = Time(sec=ns // 10**9, nanosec=ns % 10**9)
            r, t = pose_of(scan.with_suffix(".pose"))
            qx, qy, qz, qw = quaternion(r)
            pose = Pose(position=Point(x=t[0], y=t[1], z=t[2]), orientation=Quat(x=qx, y=qy, z=qz, w=qw))
            odom = Odometry(
                header=Header(stamp=stamp, frame_id="odom"),
                child_frame_id="base_link",
                pose=PoseCov(pose=pose, covariance=np.zeros(36)),
                twist=TwistCov(twist=Twist(linear=Vector3(x=0.0, y=0.0, z=0.0), angular=Vector3(x=0.0, y=0.0, z=0.0)), covariance=np.zeros(36)),
            )
            w.write(odom_c, ns, ts.serialize_cdr(odom, Odometry.__msgtype__))
            tf = TransformStamped(
                header=Header(stamp=stamp, frame_id="odom"),
                child_frame_id="base_link",
                transform=Transform(translation=Vector3(x=t[0], y=t[1], z=t[2]), rotation=Quat(x=qx, y=qy, z=qz, w=qw)),
            )
            w.write(tf_c, ns, ts.serialize_cdr(TFMessage(transforms=[tf]), TFMessage.__msgtype__))
            raw = np.loadtxt(scan, ndmin=2)
            xyz = (raw[:, :3] / 100.0) @ C.T
            cloud = np.zeros(len(xyz), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4")])
            cloud["x"], cloud["y"], cloud["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
            cloud["intensity"] = np.arange(len(xyz)) % 256
            fields = [PointField(name=n, offset=4 * i, datatype=7, count=1) for i, n in enumerate(["x", "y", "z", "intensity"])]
            msg = PointCloud2(
                header=Header(stamp=stamp, frame_id="base_link"),
                height=1,
                width=len(xyz),
                fields=fields,
                is_bigendian=False,
                point_step=16,
                row_step=16 * len(xyz),
                data=np.frombuffer(cloud.tobytes(), dtype=np.uint8),
                is_dense=True,
            )
            w.write(points_c, ns, ts.serialize_cdr(msg, PointCloud2.__msgtype__))
    return len(scans)


def poses(out):
    doc = json.loads((out / "poses.json").read_text())
    return [np.array(s["world_from_scan"]) for s in doc["scans"]]


def match(cps_survey, inputs, out, *extra):
    shutil.rmtree(out, ignore_errors=True)
    r = subprocess.run([cps_survey, "match", *map(str, inputs), "--out", str(out), *extra], capture_output=True, text=True)
    if r.returncode != 0:
        fail(f"match {' '.join(map(str, inputs))} {' '.join(extra)}: exit {r.returncode}\n{r.stdout}\n{r.stderr}")
    return poses(out)


def main():
    cps_survey, repo, work = sys.argv[1], Path(sys.argv[2]), Path(sys.argv[3])
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    data = repo / "data" / "3dtk_dat"
    bag = work / "3dtk_bag"
    n = write_bag(data, bag)
    reference = match(cps_survey, [data], work / "from_3dtk")
    for extra in (["--odom", "/odom"], [], ["--frame", "odom"]):
        got = match(cps_survey, [bag], work / ("from_bag" + "_".join(extra).replace("/", "")), *extra)
        if len(got) != n:
            fail(f"{len(got)} scans from the bag ({extra}), {n} written")
        for k, (a, b) in enumerate(zip(reference, got)):
            d = np.linalg.inv(a) @ b
            dt = np.linalg.norm(d[:3, 3])
            da = math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(d[:3, :3]) - 1) / 2))))
            if dt > 1e-3 or da > 0.01:
                fail(f"scan {k} ({extra}): {dt * 1000:.3f} mm, {da:.4f}° from the 3DTK directory's registration")
    # match --ros2-bag: read by rosbags and mcap-ros2-support.
    out, written = work / "with_bag", work / "written_bag"
    registered = match(cps_survey, [data], out, "--ros2-bag", str(written))
    with AnyReader([written]) as reader:
        got = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages() if c.topic == "/cps/pose"]
        clouds = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages() if c.topic == "/cps/scan"]
    if len(got) != n or len(clouds) != n:
        fail(f"match --ros2-bag: {len(got)} poses and {len(clouds)} clouds, {n} scans")
    for k, (m, t) in enumerate(zip(got, registered)):
        p = m.pose.pose.position
        if max(abs(p.x - t[0, 3]), abs(p.y - t[1, 3]), abs(p.z - t[2, 3])) > 1e-12:
            fail(f"match --ros2-bag: scan {k} at ({p.x}, {p.y}, {p.z}), poses.json {t[:3, 3]}")
    (mcap_file,) = written.glob("*.mcap")
    with open(mcap_file, "rb") as f:
        decoded = sum(1 for _ in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages())
    if decoded != 3 * n + 1:
        fail(f"match --ros2-bag: mcap-ros2-support decoded {decoded} messages, expected {3 * n + 1}")
    print(f"check_ros2_match: {n} real scans in a rosbags-written bag register as from their 3DTK directory, and match's own bag reads back: ok")


main()
