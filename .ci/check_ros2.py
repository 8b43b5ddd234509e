"""The rosbag2 a run writes, read by the ROS 2 ecosystem's own readers:
rosbags (AnyReader on the directory, every message deserialised with the
bag's embedded definitions) and mcap + mcap-ros2-support (the format
authors' reader and ROS 2 decoder). Both must see the same messages, and
what they decode must agree with report.json, the journal and the scans.

    python check_ros2.py RUN_DIR [BAG]   (a run with [output] ros2_bag = true;
                                           BAG: another bag of it, default RUN_DIR/rosbag2)
"""

import json
import math
import sys
from pathlib import Path

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader


def fail(msg):
    print(f"check_ros2: {msg}", file=sys.stderr)
    sys.exit(1)


def main():
    run = Path(sys.argv[1])
    bag = Path(sys.argv[2]) if len(sys.argv) > 2 else run / "rosbag2"
    report = json.loads((run / "report.json").read_text())
    journal = [json.loads(l) for l in (run / "journal.jsonl").read_text().splitlines()]
    scans = [e for e in journal if e["event"] == "scan"]
    fixes = {e["station"]: e["data"] for e in journal if e["event"] == "fix"}

    # rosbags: every message of every topic.
    by_topic = {}
    with AnyReader([bag]) as reader:
        for conn, stamp, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            by_topic.setdefault(conn.topic, []).append((conn.msgtype, stamp, msg))
    counts = {t: len(v) for t, v in by_topic.items()}

    # mcap + mcap-ros2-support: the same counts, decoded by another decoder.
    mcap_counts = {}
    (mcap_file,) = bag.glob("*.mcap")
    with open(mcap_file, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        if reader.get_header().profile != "ros2":
            fail(f"MCAP profile {reader.get_header().profile!r}, expected 'ros2'")
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            if schema.encoding != "ros2msg" or channel.message_encoding != "cdr":
                fail(f"{channel.topic}: schema {schema.encoding}, messages {channel.message_encoding}")
            mcap_counts[channel.topic] = mcap_counts.get(channel.topic, 0) + 1
            if channel.topic == "/cps/scan" and decoded.width * decoded.point_step != len(decoded.data):
                fail("/cps/scan: width × point_step differs from the data's length (mcap_ros2)")
    if mcap_counts != counts:
        fail(f"rosbags counts {counts} but mcap {mcap_counts}")

    # The scans: one PointCloud2 each, with the journal's point counts.
    clouds = by_topic.get("/cps/scan", [])
    if [c[2].width * c[2].height for c in clouds] != [s["data"]["points"] for s in scans]:
        fail(f"/cps/scan point counts {[c[2].width for c in clouds]}, journal {[s['data']['points'] for s in scans]}")
    for _, stamp, c in clouds:
        names = [f.name for f in c.fields]
        if names[:3] != ["x", "y", "z"] or c.header.frame_id != "parent/scanner":
            fail(f"/cps/scan fields {names}, frame {c.header.frame_id}")
        if stamp != c.header.stamp.sec * 10**9 + c.header.stamp.nanosec:
            fail("/cps/scan: log time differs from the header's stamp")

    # The parent's poses at its fixes: the journal's, covariance mapped
    # (x, y, z, θ) → (x, y, z, rotZ).
    poses = by_topic.get("/cps/parent/pose", [])
    stations = {s["index"]: s for s in report["stations"]}
    matched = 0
    for _, _, m in poses:
        p = m.pose.pose.position
        q = m.pose.pose.orientation
        heading = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
        for k, s in stations.items():
            e = s["pose"]
            if abs(e["x_m"] - p.x) < 1e-9 and abs(e["y_m"] - p.y) < 1e-9 and abs(e["z_m"] - p.z) < 1e-9:
                if abs(math.remainder(e["heading_rad"] - heading, 2 * math.pi)) > 1e-9:
                    fail(f"station {k}: heading {heading} in the bag, {e['heading_rad']} in report.json")
                c = m.pose.covariance.reshape(6, 6)
                ours = s["covariance"]
                at = [0, 1, 2, 5]
                worst = max(abs(c[at[i]][at[j]] - ours[i][j]) for i in range(4) for j in range(4))
                if worst > 1e-15:
                    fail(f"station {k}: covariance differs by {worst:e}")
                matched += 1
                break
    fixed = [k for k in stations if k in fixes]
    if matched < len(fixed):
        fail(f"{matched} parent poses match report.json's stations; {len(fixed)} stations were fixed")

    # tf: map → parent/base_link at every parent pose; the static mount.
    tf = [t for _, _, m in by_topic.get("/tf", []) for t in m.transforms]
    parents = [t for t in tf if t.header.frame_id == "map" and t.child_frame_id == "parent/base_link"]
    if len(parents) != len(poses):
        fail(f"{len(parents)} map → parent/base_link transforms, {len(poses)} parent poses")
    static = [t for _, _, m in by_topic.get("/tf_static", []) for t in m.transforms]
    if [(t.header.frame_id, t.child_frame_id) for t in static] != [("parent/base_link", "parent/scanner")]:
        fail(f"/tf_static holds {[(t.header.frame_id, t.child_frame_id) for t in static]}")

    # The children where the adjustment puts them.
    points = {p["id"]: p for p in report["adjustment"]["points"] if not p["control"]}
    children = [(t, m) for t, v in by_topic.items() if t.endswith("/pose") and t != "/cps/parent/pose" for m in v]
    if len(children) != len(points):
        fail(f"{len(children)} child poses, {len(points)} placements adjusted")
    for _, (_, _, m) in children:
        p = m.pose.pose.position
        if not any(abs(a["x_m"] - p.x) < 1e-9 and abs(a["y_m"] - p.y) < 1e-9 for a in points.values()):
            fail(f"a child pose at ({p.x}, {p.y}) matches no adjusted placement")

    # Paths and markers.
    (plan,) = [m for _, _, m in by_topic["/cps/plan"]]
    if len(plan.poses) != report["adjustment"]["stations"][-1]["index"] + 1 and len(plan.poses) < len(stations):
        fail(f"/cps/plan has {len(plan.poses)} poses")
    (route,) = [m for _, _, m in by_topic["/cps/route"]]
    if len(route.poses) != len(fixes):
        fail(f"/cps/route has {len(route.poses)} poses, the journal {len(fixes)} fixes")
    (ellipses,) = [m for _, _, m in by_topic["/cps/ellipses"]]
    adjusted = report["adjustment"]["stations"]
    if len(ellipses.markers) != len(adjusted):
        fail(f"/cps/ellipses has {len(ellipses.markers)} markers, {len(adjusted)} stations adjusted")
    for mk, s in zip(ellipses.markers, adjusted):
        if abs(mk.scale.x - 2 * s["ellipse_95"]["semi_major_m"]) > 1e-12:
            fail(f"station {s['index']}: ellipse {mk.scale.x} vs {2 * s['ellipse_95']['semi_major_m']}")
    if report["crs"]["name"] not in (bag / "metadata.yaml").read_text():
        fail("metadata.yaml does not name the CRS")
    print(f"check_ros2: {sum(counts.values())} messages on {len(counts)} topics read by rosbags and mcap-ros2: ok")


main()
