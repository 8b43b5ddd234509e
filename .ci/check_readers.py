"""The deliverables read by readers that neither wrote them nor are used by
check_deliverables.py (issue 33):

- LASzip (PyPI `laszip`, as laspy's LazBackend.Laszip) reads LAS, LAZ and
  COPC sequentially, every point, equal to the LAS;
- copc-lib (PyPI `copclib`) answers box queries with exactly the points a
  brute-force count on the LAS finds;
- a LAS 1.4 R15 conformance check written from the specification's
  tables: legacy counts 0 for format 6, bounds equal to the records'
  extremes, global encoding (GPS time type and WKT bits);
- pyproj (PROJ) identifies the EPSG code of every written EPSG CRS;
- GDAL's `gdalsrsinfo` (Debian's gdal-bin: GDAL 3.6 on PROJ 9.1) parses every
  written CRS, the default local frame included.

    check_readers.py SITE_RUN COMPOUND_RUN LOCAL_RUN

SITE_RUN: `[site] crs = "EPSG:25832"` with las, laz and copc (the hall); COMPOUND_RUN:
`crs = "EPSG:7415"` (RD New + NAP height) with las; LOCAL_RUN: no `[site]`.
"""

import json
import struct
import subprocess
import sys
from pathlib import Path

import copclib
import laspy
import numpy as np
import pyproj

site, compound, local = (Path(p) for p in sys.argv[1:4])


def xyz(las):
    return np.column_stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)])


def sorted_rows(a):
    return a[np.lexsort(a.T[::-1])]


# LASzip, sequentially, every file.
reference = laspy.read(site / "cloud.las")
ref = xyz(reference)
for name in ["cloud.las", "cloud.laz", "cloud.copc.laz"]:
    las = laspy.read(site / name, laz_backend=laspy.LazBackend.Laszip)
    got = xyz(las)
    assert len(got) == len(ref) == las.header.point_count, (name, len(got), len(ref))
    assert np.array_equal(sorted_rows(got), sorted_rows(ref)), f"{name}: LASzip's points differ from the LAS"
    print(f"LASzip: {name}: {len(got)} points, equal to the LAS")

# copc-lib's box queries against a brute-force count.
reader = copclib.FileReader(str(site / "cloud.copc.laz"))
header = reader.copc_config.las_header
info = reader.copc_config.copc_info
cube_min = np.array([info.center_x, info.center_y, info.center_z]) - info.halfsize
header_min = np.array([header.min.x, header.min.y, header.min.z])
assert np.allclose(cube_min, header_min, rtol=0, atol=1e-9), (cube_min, header_min)
x, y, z = ref.T
rng = np.random.default_rng(33)
lo_all, hi_all = ref.min(axis=0), ref.max(axis=0)
for k in range(200):
    lo = rng.uniform(lo_all, hi_all)
    hi = lo + rng.uniform(0.05, 1.0, 3) * (hi_all - lo_all)
    got = len(reader.GetPointsWithinBox(copclib.Box(*lo, *hi)))
    want = int(np.sum((x >= lo[0]) & (x <= hi[0]) & (y >= lo[1]) & (y <= hi[1]) & (z >= lo[2]) & (z <= hi[2])))
    assert got == want, f"box {k} {lo}–{hi}: copc-lib returns {got} points, the LAS holds {want}"
print(f"copc-lib: 200 box queries equal to brute-force counts; cube min = header min")


# LAS 1.4 R15 conformance from the specification's tables.
def conformance(path):
    b = path.read_bytes()
    ge = struct.unpack_from("<H", b, 6)[0]
    fmt = b[104] & 0x3F
    legacy = struct.unpack_from("<6I", b, 107)
    bounds = struct.unpack_from("<6d", b, 179)
    count = struct.unpack_from("<Q", b, 247)[0]
    las = laspy.read(path)
    p = xyz(las)
    extremes = (p[:, 0].max(), p[:, 0].min(), p[:, 1].max(), p[:, 1].min(), p[:, 2].max(), p[:, 2].min())
    assert (b[24], b[25]) == (1, 4), (path, b[24], b[25])
    assert fmt == 6, (path, fmt)
    assert legacy == (0,) * 6, f"{path.name}: legacy counts {legacy}: R15 requires 0 for formats 6–10"
    assert count == len(p), (path, count, len(p))
    assert bounds == tuple(float(e) for e in extremes), f"{path.name}: bounds {bounds} against {extremes}"
    assert ge & 0x10, f"{path.name}: global encoding {ge:#b}: the WKT bit is required for formats 6–10"
    assert ge & ~0x11 == 0, f"{path.name}: global encoding {ge:#b}: bits other than GPS time type and WKT"
    print(f"LAS 1.4 R15: {path.name}: legacy counts 0, bounds exact, global encoding {ge:#06b}")


for name in ["cloud.las", "cloud.laz", "cloud.copc.laz"]:
    conformance(site / name)
conformance(compound / "cloud.las")


def las_wkt(path):
    header = laspy.read(path).header
    for vlr in list(header.vlrs) + list(getattr(header, "evlrs", None) or []):
        if vlr.user_id == "LASF_Projection" and vlr.record_id == 2112:
            raw = getattr(vlr, "string", None) or vlr.record_data_bytes()
            return (raw.decode() if isinstance(raw, bytes) else raw).rstrip("\0")
    raise AssertionError(f"{path}: no WKT VLR")


def gdal_parses(wkt, what):
    run = subprocess.run(["gdalsrsinfo", "-o", "wkt1", wkt], capture_output=True, text=True)
    assert run.returncode == 0 and "ERROR" not in run.stderr, f"gdalsrsinfo refuses {what}: {run.stderr}"
    return run.stdout


# PROJ identifies the codes; GDAL parses every CRS written.
for run, code in [(site, 25832), (compound, 7415)]:
    wkt = las_wkt(run / "cloud.las")
    report = json.loads((run / "report.json").read_text())["crs"]
    assert report["wkt"] == wkt and report["epsg"] == code, report
    crs = pyproj.CRS.from_wkt(wkt)
    assert crs.to_epsg() == code, f"pyproj identifies {crs.to_epsg()} for EPSG:{code}: {wkt}"
    assert not crs.is_bound, f"EPSG:{code} reads as a bound CRS (TOWGS84)"
    assert laspy.read(run / "cloud.las").header.parse_crs().to_epsg() == code
    gdal_parses(wkt, f"EPSG:{code}")
    print(f"pyproj {pyproj.__version__} (PROJ {pyproj.proj_version_str}) identifies EPSG:{code}; gdalsrsinfo parses it")
assert pyproj.CRS.from_wkt(las_wkt(compound / "cloud.las")).is_compound
local_wkt = json.loads((local / "report.json").read_text())["crs"]["wkt"]
assert local_wkt.startswith("LOCAL_CS["), local_wkt
out = gdal_parses(local_wkt, "the default local frame")
assert out.strip().startswith("LOCAL_CS["), out
assert pyproj.CRS.from_wkt(local_wkt).is_engineering
print("gdalsrsinfo (GDAL 3.6 / PROJ 9.1) and pyproj parse the default local frame")
