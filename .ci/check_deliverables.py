"""The deliverables of a georeferenced run, read by independent readers:
laspy with lazrs (LAS, LAZ, COPC through laspy's own COPC reader), pye57
(libE57Format) and plyfile.

    check_deliverables.py RUN_DIR

RUN_DIR is a run with `[site] crs = "EPSG:25832"` and `[output] formats`
holding ply, las, laz, copc and e57. Checked: point counts, the CRS in every
format that carries one, each LAS point's scan (point_source_id) and time
(adjusted standard GPS time = the journal's UNIX time − 315,964,800 s + 18
leap seconds − 10⁹), LAZ and COPC holding the LAS's points, one E57 data3D
per scan whose points (pose applied by libE57Format's reader) equal the
LAS's points of that scan to 0.1 mm, and the PLY's CRS comments.
"""

import json
import sys
from pathlib import Path

import laspy
import numpy as np
import plyfile
import pye57

run = Path(sys.argv[1])
report = json.loads((run / "report.json").read_text())
wkt = report["crs"]["wkt"]
assert report["crs"]["name"] == "EPSG:25832", report["crs"]
scans = [json.loads(l) for l in (run / "journal.jsonl").read_text().splitlines()]
scans = [e for e in scans if e["event"] == "scan"]
times = {e["station"]: e["data"]["unix_time_s"] - 315_964_800 + 18 - 1e9 for e in scans}
counts = {e["station"]: e["data"]["points"] for e in scans}


def wkt_of(header):
    for vlr in list(header.vlrs) + list(getattr(header, "evlrs", None) or []):
        if vlr.user_id == "LASF_Projection" and vlr.record_id == 2112:
            raw = getattr(vlr, "string", None) or getattr(vlr, "record_data_bytes", lambda: b"")()
            return raw.decode() if isinstance(raw, bytes) else raw
    raise AssertionError("no WKT VLR")


def xyz(las):
    return np.column_stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)])


las = laspy.read(run / "cloud.las")
assert las.header.version.major == 1 and las.header.version.minor == 4, las.header.version
assert las.header.point_format.id == 6, las.header.point_format.id
assert wkt_of(las.header).rstrip("\0") == wkt
assert las.header.global_encoding.wkt, "global encoding: WKT bit"
assert las.header.global_encoding.gps_time_type == laspy.header.GpsTimeType.STANDARD
source = np.asarray(las.point_source_id)
per_scan = {int(s): int(n) for s, n in zip(*np.unique(source, return_counts=True))}
assert per_scan == counts, (per_scan, counts)
want_time = np.array([times[int(s)] for s in source])
assert np.max(np.abs(np.asarray(las.gps_time) - want_time)) < 1e-6
points = xyz(las)
print(f"LAS: {len(points)} points, format 6, {len(per_scan)} scans, WKT CRS, times per scan")

laz = laspy.read(run / "cloud.laz")
assert wkt_of(laz.header).rstrip("\0") == wkt
assert np.array_equal(xyz(laz), points) and np.array_equal(np.asarray(laz.point_source_id), source)
print(f"LAZ: the LAS's {len(points)} points ({(run / 'cloud.laz').stat().st_size} of {(run / 'cloud.las').stat().st_size} bytes)")

with laspy.CopcReader.open(str(run / "cloud.copc.laz")) as copc:
    octree = copc.query()
    assert wkt_of(copc.header).rstrip("\0") == wkt
assert len(octree) == len(points), (len(octree), len(points))
key = lambda a: a[np.lexsort(a.T)]
assert np.max(np.abs(key(xyz(octree)) - key(points))) < 1e-9
print(f"COPC: {len(octree)} points in the octree, the LAS's")

e57 = pye57.E57(str(run / "cloud.e57"))
assert e57.scan_count == len(scans), (e57.scan_count, len(scans))
root = e57.image_file.root()
assert root["coordinateMetadata"].value() == wkt
fused = report["fusion"]["scans"]
guids = {root["guid"].value()}
for k, f in enumerate(fused):
    header = e57.get_header(k)
    station = f["station"]
    assert header["name"].value() == f"scan{station:03d}", header["name"].value()
    guids.add(header["guid"].value())
    t = header.translation
    assert np.allclose(t, [f["pose"]["x_m"], f["pose"]["y_m"], f["pose"]["z_m"]], atol=1e-6), (t, f["pose"])
    data = e57.read_scan(k, transform=True, ignore_missing_fields=True)
    got = np.column_stack([data["cartesianX"], data["cartesianY"], data["cartesianZ"]])
    want = points[source == station]
    assert got.shape == want.shape, (got.shape, want.shape)
    assert np.max(np.abs(got - want)) < 1.5e-4, np.max(np.abs(got - want))
assert len(guids) == len(fused) + 1, "every GUID unique"
print(f"E57 (libE57Format): {e57.scan_count} data3D, one per scan at its fused pose, points = the LAS's to 0.1 mm")

ply = plyfile.PlyData.read(str(run / "cloud.ply"))
assert f"crs EPSG:25832" in ply.comments and f"crs_wkt {wkt}" in ply.comments, ply.comments
assert len(ply["vertex"]) == len(points)
print(f"PLY (plyfile): {len(ply['vertex'])} vertices, CRS in its comments")
