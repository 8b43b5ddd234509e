"""`match` keeps every attribute its inputs carry, read by independent
readers (issue 33, item 13).

    check_attributes.py CPS_SURVEY WORKSPACE OUT_DIR

The small_gicp pair (real LiDAR frames, read with plyfile) is written by
laspy as two LAS 1.4 point format 7 files: each point an 8-bit colour
scaled to 16 bits (× 257, as LAS writers store 8-bit colour), and a unique
adjusted standard GPS time. `cps-survey match` registers them and writes
LAS, LAZ, COPC, E57 and PLY. Then, each output point paired with its input
point by its time:

- laspy (LAS, LAZ, COPC) and LASzip (LAZ, COPC: laspy's LazBackend.Laszip):
  point format 7, the GPS time type bit set, every colour and time equal
  to the input's;
- pye57 (libE57Format): each data3D's colorRed/Green/Blue (8-bit) equal to
  the input's / 257, its timeStamp + acquisitionStart equal to the input's
  GPS time (to 1 µs);
- plyfile: uchar red, green, blue equal to the input's / 257, double time
  equal to the GPS time, the header's comment saying it is GPS time.
"""

import json
import subprocess
import sys
from pathlib import Path

import laspy
import numpy as np
import plyfile
import pye57

cps, workspace, out = sys.argv[1], Path(sys.argv[2]), Path(sys.argv[3])
out.mkdir(parents=True, exist_ok=True)
rng = np.random.default_rng(33)

# GPS time of 2026-11-25 (1.448e9 s), adjusted (− 10⁹), 10 µs apart.
ADJUSTED_START = 448_000_000.0
inputs = {}
count = 0
for name in ["target", "source"]:
    vertex = plyfile.PlyData.read(workspace / "data/small_gicp_pair" / f"{name}.ply")["vertex"]
    n = vertex.count
    header = laspy.LasHeader(point_format=7, version="1.4")
    header.global_encoding.gps_time_type = laspy.header.GpsTimeType.STANDARD
    header.scales = [1e-4] * 3
    header.offsets = [0.0] * 3
    las = laspy.LasData(header)
    las.x, las.y, las.z = vertex["x"], vertex["y"], vertex["z"]
    rgb8 = rng.integers(0, 256, size=(3, n), dtype=np.uint16)
    las.red, las.green, las.blue = rgb8 * 257
    las.gps_time = ADJUSTED_START + (count + np.arange(n)) * 1e-5
    count += n
    path = out / f"{name}.las"
    las.write(path)
    inputs[name] = laspy.read(path)

# Every input point by its (unique) time: colour (16-bit) and time.
times = np.concatenate([inputs[k].gps_time for k in inputs])
colours = np.concatenate([np.stack([inputs[k].red, inputs[k].green, inputs[k].blue], axis=1) for k in inputs])
order = np.argsort(times)
times, colours = times[order], colours[order]


def lookup(t_adjusted, what):
    """The input points of these adjusted GPS times (each must exist)."""
    hi = np.clip(np.searchsorted(times, t_adjusted), 1, len(times) - 1)
    at = np.where(np.abs(times[hi - 1] - t_adjusted) < np.abs(times[hi] - t_adjusted), hi - 1, hi)
    off = np.abs(times[at] - t_adjusted)
    assert off.max() < 1e-6, f"{what}: a time {t_adjusted[off.argmax()]!r} no input point has ({off.max()} s off)"
    return at


matched = out / "matched"
run = subprocess.run(
    [cps, "match", str(out / "target.las"), str(out / "source.las"), "--out", str(matched),
     "--formats", "las,laz,copc,e57,ply", "--json"],
    capture_output=True, text=True,
)
assert run.returncode == 0, run.stderr
report = json.loads(run.stdout)


def check_las(path, backend=None):
    data = laspy.read(path, laz_backend=backend) if backend else laspy.read(path)
    what = f"{path.name}" + (f" ({backend})" if backend else "")
    assert data.header.point_format.id == 7, f"{what}: point format {data.header.point_format.id}"
    assert data.header.global_encoding.gps_time_type == laspy.header.GpsTimeType.STANDARD, what
    at = lookup(np.asarray(data.gps_time), what)
    got = np.stack([data.red, data.green, data.blue], axis=1)
    assert (got == colours[at]).all(), f"{what}: colours differ from the inputs'"
    assert len(np.unique(at)) == len(at), f"{what}: a point written twice"
    assert len(at) > 0.9 * len(times), f"{what}: {len(at)} of {len(times)} points"
    return len(at)


n = check_las(matched / "cloud.las")
for name in ["cloud.laz", "cloud.copc.laz"]:
    assert check_las(matched / name) == n, name
    assert check_las(matched / name, laspy.LazBackend.Laszip) == n, name
print(f"LAS, LAZ, COPC (laspy, LASzip): {n} points, format 7, each colour and GPS time the input's")

e57 = pye57.E57(str(matched / "cloud.e57"))
total = 0
for i in range(e57.scan_count):
    header = e57.get_header(i)
    scan = e57.read_scan(i, colors=True, ignore_missing_fields=True, transform=False)
    m = header.point_count
    stamps = np.empty(m, "d")
    buffers = pye57.libe57.VectorSourceDestBuffer()
    buffers.append(pye57.libe57.SourceDestBuffer(e57.image_file, "timeStamp", stamps, m, True, True))
    header.points.reader(buffers).read()
    start = header.node["acquisitionStart"]["dateTimeValue"].value()
    at = lookup(start + stamps - 1e9, f"cloud.e57 data3D {i}")
    got = np.stack([scan["colorRed"], scan["colorGreen"], scan["colorBlue"]], axis=1).astype(np.uint16)
    assert (got * 257 == colours[at]).all(), f"cloud.e57 data3D {i}: colours differ from the inputs'"
    total += m
assert total == n, f"cloud.e57: {total} points, the LAS {n}"
print(f"E57 (pye57): {e57.scan_count} data3D, {total} points, each colour and timeStamp the input's")

ply = plyfile.PlyData.read(matched / "cloud.ply")
assert "time: GPS seconds since 1980-01-06 00:00 UTC" in ply.comments, ply.comments
v = ply["vertex"]
for c in ["red", "green", "blue"]:
    assert v[c].dtype == np.uint8, (c, v[c].dtype)
at = lookup(np.asarray(v["time"]) - 1e9, "cloud.ply")
got = np.stack([v["red"], v["green"], v["blue"]], axis=1).astype(np.uint16)
assert (got * 257 == colours[at]).all(), "cloud.ply: colours differ from the inputs'"
assert len(at) == n, f"cloud.ply: {len(at)} points, the LAS {n}"
print(f"PLY (plyfile): {len(at)} points, uchar colour and GPS time the input's")
