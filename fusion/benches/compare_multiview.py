"""`cps-survey match`, mode by mode, beside Open3D's multiway registration
and small_gicp, on the same scans from the same starts (issue 38).

Scenarios (every reference exact but the 3DTK set's):
- parts of a real scan under known random transforms, as in
  covariance_nees.py: disjoint random shares (each part sees all of the
  scene) or 150° wedges every 90° (each overlaps its neighbours by 60°);
  the starts 0.1 m / 2° off ("near") or 0.3 m / 3° off ("rough");
- the same shares with every part's frame up to 50 m from its points
  ("far frames": a scan seen from afar);
- the 3DTK set (three scans, odometry starts); its reference is
  small_gicp GICP's own (good to about ±0.3° / 1.5 cm, data/3dtk_dat/README.md),
  so that row favours small_gicp.

    pip install open3d-cpu small_gicp==1.0.1 numpy plyfile
    cargo build --release -p missions
    python3 fusion/benches/compare_multiview.py target/release/cps-survey 8

Every tool gets the parts' points in their own frames and the same start
poses; the first part holds the frame. Cells: `match` chooses its own
(`--schedule auto`); the other two get `match`'s last cell of the same
trial (`settings.schedule`), so they work at the resolution `match` ends
at.
- Open3D 0.20, as its multiway-registration tutorial does it: each part
  voxel-downsampled at the cell, normals within 2 cells (30 neighbours),
  every pair matched by point-to-plane ICP from the starts, within 15 cells
  then 1.5 cells, with the information matrix of the fine match; a chain
  of odometry edges and the other pairs as uncertain loop closures; then
  `global_optimization` (Levenberg–Marquardt, correspondence distance 1.5
  cells, edge prune threshold 0.25, node 0 fixed).
- small_gicp 1.0.1 has no multi-view registration; its own way to build a
  map is scan to map: each part in turn is aligned by GICP to the union of
  the parts already placed, from its start, within 15 cells then 1.5
  cells, downsampled at the cell.
Times are wall seconds of the registration (`seconds` of `match --json`,
which includes its verification; the Python libraries timed around their
calls, one process, the machine's threads).

Prints, per scenario and tool: RMS and worst rotation / translation error
over the parts but the first, parts off by more than 1° or 0.1 m, how many
of those `match` flagged (exit 1, the part named in `untrusted`), and the
median time. Environment: MV_ONLY=NAME runs the scenarios whose label
contains NAME; MV_TOOLS=graph,open3d,... a subset of the tools;
MV_VERBOSE=1 prints why a run of `match` failed (exit 2).
"""
import json
import math
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from covariance_nees import random_pose, read_3dtk, shares, sources, wedges, xi  # noqa: E402
from global_success import DATA, write_ply  # noqa: E402

MODES = ["graph", "pairwise", "incremental", "simultaneous"]
OFF_RAD, OFF_M = math.radians(1.0), 0.1


def match(tool, d, parts, starts, mode):
    files = []
    for i, p in enumerate(parts):
        f = os.path.join(d, f"part{i}.ply")
        write_ply(f, p)
        files.append(f)
    init = os.path.join(d, "init.json")
    with open(init, "w") as out:
        json.dump([{"file": os.path.basename(f), "world_from_scan": s.tolist()} for f, s in zip(files, starts)], out)
    r = subprocess.run([tool, "match", *files, "--init-poses", init, "--mode", mode,
                        "--out", os.path.join(d, "out"), "--json"], capture_output=True, text=True)
    try:
        v = json.loads(r.stdout)
    except json.JSONDecodeError:
        return None, r.returncode, set(), r.stderr.strip()[:200], None
    poses = [np.array(s["world_from_scan"]) for s in v["scans"]]
    cell = v["settings"]["schedule"][-1][0]
    return poses, r.returncode, set(v.get("untrusted", [])), v["seconds"], cell


def open3d_multiway(parts, starts, cell):
    import open3d as o3d

    reg = o3d.pipelines.registration
    t0 = time.perf_counter()
    clouds = []
    for p, s in zip(parts, starts):
        c = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p @ s[:3, :3].T + s[:3, 3]))
        c = c.voxel_down_sample(cell)
        c.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2 * cell, max_nn=30))
        clouds.append(c)
    coarse, fine = 15 * cell, 1.5 * cell
    plane = reg.TransformationEstimationPointToPlane()
    graph = reg.PoseGraph()
    odometry = np.eye(4)
    graph.nodes.append(reg.PoseGraphNode(odometry))
    n = len(clouds)
    for a in range(n):
        for b in range(a + 1, n):
            first = reg.registration_icp(clouds[a], clouds[b], coarse, np.eye(4), plane)
            second = reg.registration_icp(clouds[a], clouds[b], fine, first.transformation, plane)
            info = reg.get_information_matrix_from_point_clouds(clouds[a], clouds[b], fine, second.transformation)
            if b == a + 1:
                odometry = second.transformation @ odometry
                graph.nodes.append(reg.PoseGraphNode(np.linalg.inv(odometry)))
                graph.edges.append(reg.PoseGraphEdge(a, b, second.transformation, info, uncertain=False))
            else:
                graph.edges.append(reg.PoseGraphEdge(a, b, second.transformation, info, uncertain=True))
    option = reg.GlobalOptimizationOption(max_correspondence_distance=fine, edge_prune_threshold=0.25,
                                          reference_node=0)
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        reg.global_optimization(graph, reg.GlobalOptimizationLevenbergMarquardt(),
                                reg.GlobalOptimizationConvergenceCriteria(), option)
    seconds = time.perf_counter() - t0
    # Node poses map each (started) part into part 0's started frame.
    return [starts[0] @ graph.nodes[i].pose @ s for i, s in enumerate(starts)], seconds


def small_gicp_scan_to_map(parts, starts, cell):
    import small_gicp

    t0 = time.perf_counter()
    poses = [starts[0]]
    placed = [parts[0] @ starts[0][:3, :3].T + starts[0][:3, 3]]
    for p, s in zip(parts[1:], starts[1:]):
        target = np.concatenate(placed)
        guess = s
        for distance in (15 * cell, 1.5 * cell):
            r = small_gicp.align(target, p, guess, registration_type="GICP", downsampling_resolution=cell,
                                 max_correspondence_distance=distance)
            guess = r.T_target_source
        poses.append(guess)
        placed.append(p @ guess[:3, :3].T + guess[:3, 3])
    return poses, time.perf_counter() - t0


def errors(poses, truths):
    out = []
    for i in range(1, len(truths)):
        # Relative to part 0, as every tool holds it where it started.
        e = xi(np.linalg.inv(poses[0]) @ poses[i], np.linalg.inv(truths[0]) @ truths[i])
        out.append((np.linalg.norm(e[:3]), np.linalg.norm(e[3:])))
    return out


def cut_scenarios():
    out = []
    for name, xyz, up in sources():
        out.append((f"{name} shares near", lambda rng, xyz=xyz: shares(rng, xyz, 4), up, 2, 0.1, 0.5))
        out.append((f"{name} shares far frames", lambda rng, xyz=xyz: shares(rng, xyz, 4), up, 2, 0.1, 50.0))
        if name != "3dtk-scan001":  # its scans leave out the quarter behind the robot
            for label, turn, move in (("near", 2, 0.1), ("rough", 3, 0.3)):
                out.append((f"{name} wedges {label}",
                            lambda rng, xyz=xyz, up=up: wedges(xyz, up, 4, 150.0), up, turn, move, 0.5))
    return out


def three_dtk():
    from compare_icp import pose

    parts = [read_3dtk(os.path.join(DATA, "3dtk_dat", f"scan{k:03d}.3d")) for k in range(3)]
    starts = [pose(k) for k in range(3)]
    r01 = np.loadtxt(os.path.join(DATA, "3dtk_dat", "reference_T_scan000_scan001.txt"))
    r12 = np.loadtxt(os.path.join(DATA, "3dtk_dat", "reference_T_scan001_scan002.txt"))
    truths = [starts[0], starts[0] @ r01, starts[0] @ r01 @ r12]
    return parts, truths, starts


def main():
    tool, trials = sys.argv[1], int(sys.argv[2])
    tools = os.environ.get("MV_TOOLS", ",".join(MODES + ["open3d", "small_gicp"])).split(",")
    only = os.environ.get("MV_ONLY")
    rng = np.random.default_rng(11)
    cases = []  # (label, generator of (parts in own frames, truths, starts))
    for label, cut, up, turn, move, frame in cut_scenarios():

        def trial(rng, cut=cut, up=up, turn=turn, move=move, frame=frame):
            pieces = cut(rng)
            truths = [np.eye(4)] + [random_pose(rng, up, 45, 2, frame) for _ in pieces[1:]]
            starts = [np.eye(4)] + [random_pose(rng, up, turn, turn, move / math.sqrt(3)) @ t for t in truths[1:]]
            local = [(p - t[:3, 3]) @ t[:3, :3] for p, t in zip(pieces, truths)]
            return local, truths, starts

        cases.append((label, trial, trials))
    cases.append(("3dtk set (3 scans), odometry", lambda rng: three_dtk(), 1))
    print(f"{'scenario':34} {'tool':12} {'RMS error':>17} {'worst':>17} {'off':>5} {'flagged':>7} {'time':>7}")
    with tempfile.TemporaryDirectory() as d:
        for label, make, n in cases:
            if only and only not in label:
                continue
            rows = {t: {"err": [], "off": 0, "flagged": 0, "secs": [], "failed": 0} for t in tools}
            for _ in range(n):
                parts, truths, starts = make(rng)
                cell = None
                for t in [m for m in MODES if m in tools] + [t for t in tools if t not in MODES]:
                    row = rows[t]
                    untrusted = set()
                    if t in MODES:
                        poses, code, untrusted, secs, c = match(tool, d, parts, starts, t)
                        if poses is None:
                            row["failed"] += 1
                            if os.environ.get("MV_VERBOSE"):
                                print(f"  {label} {t}: exit {code}: {secs}")
                            continue
                        cell = cell or c
                    elif t == "open3d":
                        poses, secs = open3d_multiway(parts, starts, cell or match(tool, d, parts, starts, "graph")[4])
                    else:
                        poses, secs = small_gicp_scan_to_map(parts, starts,
                                                            cell or match(tool, d, parts, starts, "graph")[4])
                    row["secs"].append(secs)
                    for i, (r, m) in enumerate(errors(poses, truths), start=1):
                        row["err"].append((r, m))
                        if r > OFF_RAD or m > OFF_M:
                            row["off"] += 1
                            row["flagged"] += i in untrusted
            for t in tools:
                row = rows[t]
                if not row["err"]:
                    print(f"{label:34} {t:12} failed {row['failed']}")
                    continue
                e = np.array(row["err"])
                rms = np.sqrt(np.mean(e ** 2, axis=0))
                worst = e.max(axis=0)
                flagged = f"{row['flagged']}" if t in MODES else "–"
                failed = f" (exit 2: {row['failed']})" if row["failed"] else ""
                print(f"{label:34} {t:12} {math.degrees(rms[0]):7.3f}° {rms[1] * 1e3:7.1f} mm "
                      f"{math.degrees(worst[0]):7.2f}° {worst[1] * 1e3:7.1f} mm {row['off']:5} {flagged:>7} "
                      f"{np.median(row['secs']):6.2f}s{failed}")
                sys.stdout.flush()


if __name__ == "__main__":
    main()
