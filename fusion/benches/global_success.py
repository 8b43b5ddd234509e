"""Success rate and time of `cps-survey match --init global` (issue 38).

For each real pair in data/ (the PCL room pair, small_gicp's pair) the
source scan is turned by a random angle about a random near-vertical axis
(0–180°) and moved up to 2 m; the pair is then matched from no guess.
Success: within 0.5° and 5 cm of the truth (the pair's reference composed
with the random motion). Prints one line per pair and a summary.

    python3 fusion/benches/global_success.py target/release/cps-survey 20

With Open3D installed (`pip install open3d-cpu`), each trial is also run
through Open3D's own pipeline on the same clouds: voxel downsampling at
the same cell, normals within two cells, FPFH within five (100 neighbours
at most), `registration_ransac_based_on_feature_matching` (mutual filter,
1.5 cells, three points, the edge-length 0.9 and distance checkers,
100,000 draws at 0.999), then point-to-plane ICP within two cells on the
same downsampled clouds.
"""
import json
import math
import os
import struct
import subprocess
import sys
import tempfile
import time

import numpy as np
from plyfile import PlyData, PlyElement

HERE = os.path.dirname(os.path.abspath(__file__))
DATA = os.path.join(HERE, "..", "..", "data")


def lzf_decompress(data, size):
    out = bytearray()
    i = 0
    while i < len(data):
        ctrl = data[i]
        i += 1
        if ctrl < 32:
            out += data[i:i + ctrl + 1]
            i += ctrl + 1
        else:
            length = ctrl >> 5
            ref = len(out) - ((ctrl & 0x1F) << 8) - 1
            if length == 7:
                length += data[i]
                i += 1
            ref -= data[i]
            i += 1
            for _ in range(length + 2):
                out.append(out[ref])
                ref += 1
    assert len(out) == size
    return bytes(out)


def read_pcd(path):
    raw = open(path, "rb").read()
    end = raw.index(b"DATA binary_compressed\n") + len(b"DATA binary_compressed\n")
    header = raw[:end].decode()
    n = int([l for l in header.splitlines() if l.startswith("POINTS")][0].split()[1])
    csize, usize = struct.unpack("<II", raw[end:end + 8])
    buf = lzf_decompress(raw[end + 8:end + 8 + csize], usize)
    xyz = np.frombuffer(buf, dtype="<f4").reshape(3, n).T
    return xyz[np.isfinite(xyz).all(axis=1)].astype(np.float64)


def read_ply(path):
    v = PlyData.read(path)["vertex"]
    return np.stack([v["x"], v["y"], v["z"]], axis=1).astype(np.float64)


def write_ply(path, xyz):
    a = np.zeros(len(xyz), dtype=[("x", "f4"), ("y", "f4"), ("z", "f4")])
    a["x"], a["y"], a["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    PlyData([PlyElement.describe(a, "vertex")]).write(path)


def matrix(path):
    return np.loadtxt(path).reshape(4, 4)


def rotation(axis, angle):
    axis = axis / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def open3d_run(target, source, voxel):
    import open3d as o3d
    def prepared(xyz):
        pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(xyz))
        down = pc.voxel_down_sample(voxel)
        down.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2 * voxel, max_nn=30))
        fpfh = o3d.pipelines.registration.compute_fpfh_feature(
            down, o3d.geometry.KDTreeSearchParamHybrid(radius=5 * voxel, max_nn=100))
        return down, fpfh
    started = time.time()
    (t, ft), (s_, fs) = prepared(target), prepared(source)
    reg = o3d.pipelines.registration
    r = reg.registration_ransac_based_on_feature_matching(
        s_, t, fs, ft, True, 1.5 * voxel, reg.TransformationEstimationPointToPoint(False), 3,
        [reg.CorrespondenceCheckerBasedOnEdgeLength(0.9), reg.CorrespondenceCheckerBasedOnDistance(1.5 * voxel)],
        reg.RANSACConvergenceCriteria(100000, 0.999))
    icp = reg.registration_icp(s_, t, 2 * voxel, r.transformation, reg.TransformationEstimationPointToPlane())
    return icp.transformation, time.time() - started


def error(truth, got):
    e = np.linalg.inv(truth) @ got
    deg = math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(e[:3, :3]) - 1) / 2))))
    return deg, np.linalg.norm(e[:3, 3])


def main():
    tool, trials = sys.argv[1], int(sys.argv[2])
    rng = np.random.default_rng(1)
    pairs = [
        ("room", read_pcd(os.path.join(DATA, "pcl_room_scans/room_scan1.pcd")),
         read_pcd(os.path.join(DATA, "pcl_room_scans/room_scan2.pcd")),
         matrix(os.path.join(DATA, "pcl_room_scans/reference_T_scan1_scan2.txt"))),
        ("small_gicp", read_ply(os.path.join(DATA, "small_gicp_pair/target.ply")),
         read_ply(os.path.join(DATA, "small_gicp_pair/source.ply")),
         matrix(os.path.join(DATA, "small_gicp_pair/T_target_source.txt"))),
    ]
    try:
        import open3d  # noqa: F401
        with_open3d = True
    except ImportError:
        with_open3d = False
    summary = []
    with tempfile.TemporaryDirectory() as d:
        for name, target, source, reference in pairs:
            write_ply(os.path.join(d, "target.ply"), target)
            ok, seconds, o3d_ok, o3d_seconds = 0, [], 0, []
            for t in range(trials):
                m = np.eye(4)
                m[:3, :3] = rotation(np.array([rng.normal(0, 0.05), rng.normal(0, 0.05), 1.0]),
                                     math.radians(rng.uniform(0, 180)) * rng.choice([-1, 1]))
                m[:3, 3] = rng.uniform(-1, 1, 3) * np.array([2 / math.sqrt(3)] * 3)
                moved = source @ m[:3, :3].T + m[:3, 3]
                write_ply(os.path.join(d, "source.ply"), moved)
                truth = reference @ np.linalg.inv(m)
                started = time.time()
                r = subprocess.run([tool, "match", os.path.join(d, "target.ply"), os.path.join(d, "source.ply"),
                                    "--init", "global", "--out", os.path.join(d, "out"), "--json"],
                                   capture_output=True, text=True)
                seconds.append(time.time() - started)
                try:
                    v = json.loads(r.stdout)
                except json.JSONDecodeError:
                    print(name, t, "exit", r.returncode, r.stderr.strip()[:200])
                    continue
                got = np.array(v["scans"][1]["world_from_scan"])
                deg, metres = error(truth, got)
                good = deg < 0.5 and metres < 0.05
                ok += good
                line = (f"{name} {t}: exit {r.returncode}, {deg:.3f}° {metres * 1e3:.1f} mm "
                        f"{'ok' if good else 'FAILED'}, {seconds[-1]:.2f} s, global {v['settings']['global']['seconds']:.2f} s")
                if with_open3d:
                    got, took = open3d_run(target, moved, v["settings"]["global"]["voxel_m"])
                    odeg, ometres = error(truth, got)
                    ogood = odeg < 0.5 and ometres < 0.05
                    o3d_ok += ogood
                    o3d_seconds.append(took)
                    line += f"; Open3D {odeg:.3f}° {ometres * 1e3:.1f} mm {'ok' if ogood else 'FAILED'}, {took:.2f} s"
                print(line)
            summary.append(f"{name}: {ok}/{trials} within 0.5° / 5 cm, median {np.median(seconds):.2f} s a run")
            if with_open3d:
                summary.append(f"{name} Open3D: {o3d_ok}/{trials}, median {np.median(o3d_seconds):.2f} s a run")
    print("\n".join(summary))


if __name__ == "__main__":
    main()
