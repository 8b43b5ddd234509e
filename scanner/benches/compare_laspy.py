"""LAS/LAZ writing and reading by laspy (with lazrs) on as many points as
scanner's `files` benchmark group (259,920 points, point format 6): the first
points of the hall's cloud.las. Run from the repository root after the CI's
site run (`.ci/run` writes target/ci-site/cloud.las):

    target/ci-venv/bin/python scanner/benches/compare_laspy.py
"""
import time, laspy, numpy as np
src = laspy.read("target/ci-site/cloud.las")
n = 259_920
pts = laspy.ScaleAwarePointRecord.zeros(n, header=src.header)
pts.array[:] = src.points.array[:n]
def best(f, reps=9):
    t = []
    for _ in range(reps):
        s = time.perf_counter(); f(); t.append(time.perf_counter() - s)
    return 1e3 * sorted(t)[len(t)//2]
def write(path, backend=None):
    h = laspy.LasHeader(point_format=6, version="1.4"); h.scales = src.header.scales; h.offsets = src.header.offsets
    las = laspy.LasData(h); las.points = pts
    las.write(path, laz_backend=backend) if backend else las.write(path)
print(f"laspy LAS write: {best(lambda: write('/tmp/b.las')):.1f} ms")
print(f"laspy LAZ write (lazrs): {best(lambda: write('/tmp/b.laz', laspy.LazBackend.Lazrs)):.1f} ms")
print(f"laspy LAZ write (lazrs-parallel): {best(lambda: write('/tmp/b2.laz', laspy.LazBackend.LazrsParallel)):.1f} ms")
print(f"laspy LAS read: {best(lambda: laspy.read('/tmp/b.las')):.1f} ms")
print(f"laspy LAZ read (lazrs): {best(lambda: laspy.read('/tmp/b.laz', laz_backend=laspy.LazBackend.Lazrs)):.1f} ms")
