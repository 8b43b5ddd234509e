"""Are `cps-survey match`'s covariances honest? (issue 38)

A reference that is exact on real data: a real scan is cut into parts —
its points dealt at random into disjoint shares (no point is in two
parts, so each keeps its own noise), or wedges by azimuth (the first at a
random azimuth each trial: fixed cuts gave the same parts every trial) that
overlap their neighbours, each point of an overlap dealt to one of its
wedges by a hash of its index (NEES_DEAL=random deals it at random;
NEES_WEDGES=shared keeps it in both, as before session 29) — and
each part is put in a frame of its own
under a known random transform (turned up to ±45° about the vertical and
±2° about the others, moved up to 0.5 m). The starts are off by 0.1 m and
2°. `match` registers the parts; for every part but the first (it holds
the frame) the error against the known transform, ξ = (ω, v) in the
world's axes about the first part's origin, is compared with the reported
covariance: NEES = ξᵀ Σ⁻¹ ξ, whose mean is 6 when Σ is honest (and 3 for
its rotation or its translation block alone).

    python3 fusion/benches/covariance_nees.py target/release/cps-survey 10

Prints one line per scenario and mode: the mean NEES and its 95 %
interval for the number of errors (χ² with 6·n degrees of freedom, / n),
the median, the RMS errors, and the parts off by more than 1° or 0.1 m
while the exit was 0 (a silent failure); and each trial's trusted parts
judged together against their joint covariance (`--joint-covariance`:
χ² with 6 per part when honest), per part — the parts of one trial share
links, so their separate NEES are not independent and the interval is
exact only for the joint one. Environment: NEES_ONLY=NAME runs one
source, NEES_CUT=shares or NEES_CUT=wedges one way of cutting (what is
not run is still drawn: every run of a seed has the same parts), NEES_VERBOSE=1 prints every part (with its departure from where the
verified pairs agree, in the modes without a link graph),
NEES_CHECKS=1 every verified pair (its RMS residual against the noise floor, and its true error),
NEES_AXES=1 the mean square error over the mean variance along each world axis,
NEES_EIG=1 the errors' mean z² along each eigendirection of the trials'
joint covariance (smallest variance first; 1 each when honest) and how
much of each direction turns the parts, NEES_KEEP=DIR keeps each trial's inputs, NEES_PARTS=K deals the shares
into K parts (4; 2 is one link alone), NEES_ARGS="--only-covered" adds
arguments to every `match`, NEES_VIEWPOINTS=1 writes the parts as PCD with
the scanner's position (VIEWPOINT) so that the verification tests free
space (PLY says nothing of it), NEES_SEED=S draws with another seed (7),
NEES_DEPARTURE_SCALES=C1,C2,… (the modes without a link graph) judges each
trial again with the departures' ξξᵀ scaled by each C (1 is what `match`
reports) and the adjustment's own error — each pose less its departure —
against the adjustment's covariance alone.
"""
import json
import math
import os
import subprocess
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from global_success import DATA, read_pcd, read_ply, rotation, write_ply  # noqa: E402


def read_3dtk(path):
    xyz = np.loadtxt(path, usecols=(0, 1, 2)) / 100.0
    r = np.linalg.norm(xyz, axis=1)
    return xyz[(r > 0.5) & (r < 32.5)]


def sources():
    return [
        ("3dtk-scan001", read_3dtk(os.path.join(DATA, "3dtk_dat/scan001.3d")), np.array([0, 1, 0])),
        ("room-scan1", read_pcd(os.path.join(DATA, "pcl_room_scans/room_scan1.pcd")), np.array([0, 0, 1])),
        ("small_gicp-target", read_ply(os.path.join(DATA, "small_gicp_pair/target.ply")), np.array([0, 0, 1])),
    ]


def random_pose(rng, up, turn_deg, tilt_deg, move_m):
    m = np.eye(4)
    tilt = rotation(rng.normal(size=3), math.radians(rng.uniform(-tilt_deg, tilt_deg)))
    m[:3, :3] = rotation(up.astype(float), math.radians(rng.uniform(-turn_deg, turn_deg))) @ tilt
    m[:3, 3] = rng.uniform(-move_m, move_m, 3)
    return m


def shares(rng, xyz, k):
    """The points dealt at random into k disjoint parts."""
    owner = rng.integers(0, k, len(xyz))
    return [xyz[owner == j] for j in range(k)]


def wedges(xyz, up, k, width_deg, first_deg=0.0):
    # Azimuth about the scan's up axis, the first wedge centred at first_deg.
    a = np.array([1.0, 0, 0]) if abs(up[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = a - up * (a @ up)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(up, e1)
    azimuth = np.arctan2(xyz @ e2, xyz @ e1)
    inside = []
    for j in range(k):
        d = azimuth - 2 * math.pi * j / k - math.radians(first_deg)
        d = np.arctan2(np.sin(d), np.cos(d))
        inside.append(np.abs(d) <= math.radians(width_deg / 2))
    inside = np.array(inside)
    if os.environ.get("NEES_WEDGES") == "shared":
        return [xyz[inside[j]] for j in range(k)]
    # A point where wedges overlap goes to one of them, picked by a hash of
    # its index (a test can cut the same): two real scans never share a
    # point (shared, the overlap's points were the same samples with the
    # same noise in both wedges). Not the index modulo their number: the
    # street's LiDAR stores its beams interleaved, and one wedge got the
    # low beams of the overlap, the other the high — no common surface.
    if os.environ.get("NEES_DEAL") == "random":
        # Each overlap point to one of its wedges at random (by a generator
        # of its own, so that the trials' draws stay the same).
        u = np.random.default_rng(len(xyz)).random(len(xyz))
        pick = np.floor(u * np.maximum(inside.sum(axis=0), 1)).astype(np.int64)
        owner = inside & (np.cumsum(inside, axis=0) - 1 == pick)
        return [xyz[owner[j]] for j in range(k)]
    count = inside.sum(axis=0).astype(np.uint64)
    h = (np.arange(len(xyz), dtype=np.uint64) * np.uint64(0x9E3779B97F4A7C15)) >> np.uint64(32)
    pick = ((h * np.maximum(count, np.uint64(1))) >> np.uint64(32)).astype(np.int64)
    owner = inside & (np.cumsum(inside, axis=0) - 1 == pick)
    return [xyz[owner[j]] for j in range(k)]


def write_pcd(path, xyz, viewpoint):
    with open(path, "w") as out:
        out.write(f"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {len(xyz)}\nHEIGHT 1\n"
                  f"VIEWPOINT {float(viewpoint[0])!r} {float(viewpoint[1])!r} {float(viewpoint[2])!r} 1 0 0 0\nPOINTS {len(xyz)}\nDATA ascii\n")
        np.savetxt(out, xyz.astype(np.float32), fmt="%.9g")


def xi(estimate, truth):
    """ξ = (ω, v) with estimate = exp(ξ)·truth (left, world axes)."""
    d = estimate @ np.linalg.inv(truth)
    c = max(-1.0, min(1.0, (np.trace(d[:3, :3]) - 1) / 2))
    angle = math.acos(c)
    w = np.array([d[2, 1] - d[1, 2], d[0, 2] - d[2, 0], d[1, 0] - d[0, 1]])
    w = w * (angle / (2 * math.sin(angle))) if angle > 1e-12 else w / 2
    return np.concatenate([w, d[:3, 3]])


def departure(scan):
    """The pose's departure ξ from where the verification's matches agree
    (the modes without a link graph) and `departure_chi2`, ξᵀ·C⁺·ξ in that
    adjustment's covariance C: how far the strategy stopped from it."""
    d = scan.get("departure")
    if d is None:
        return ""
    d = np.array(d)
    return (f", departure {np.linalg.norm(d[:3]) * 180 / math.pi:.3f}° {np.linalg.norm(d[3:]) * 1e3:.1f} mm "
            f"({scan['departure_chi2']:.1f} σ²)")


def run(tool, d, parts, truths, starts, mode):
    files = []
    for i, p in enumerate(parts):
        local = (p - truths[i][:3, 3]) @ truths[i][:3, :3]
        if os.environ.get("NEES_VIEWPOINTS"):
            # PCD with the scanner's position (the source scan's origin)
            # in the part's frame: the verification tests free space.
            f = os.path.join(d, f"part{i}.pcd")
            write_pcd(f, local, -truths[i][:3, :3].T @ truths[i][:3, 3])
        else:
            f = os.path.join(d, f"part{i}.ply")
            write_ply(f, local)
        files.append(f)
    with open(os.path.join(d, "init.json"), "w") as out:
        json.dump([{"file": os.path.basename(f), "world_from_scan": s.tolist()} for f, s in zip(files, starts)], out)
    r = subprocess.run([tool, "match", *files, "--init-poses", os.path.join(d, "init.json"), "--mode", mode,
                        "--out", os.path.join(d, "out"), "--json", "--joint-covariance",
                        *os.environ.get("NEES_ARGS", "").split()],
                       capture_output=True, text=True)
    try:
        return r.returncode, json.loads(r.stdout)
    except json.JSONDecodeError:
        return r.returncode, r.stderr.strip()


def main():
    tool, trials = sys.argv[1], int(sys.argv[2])
    modes = sys.argv[3].split(",") if len(sys.argv) > 3 else ["graph", "pairwise", "incremental", "simultaneous"]
    rng = np.random.default_rng(int(os.environ.get("NEES_SEED", "7")))
    scenarios = []

    def skipped(label):
        source, cut = label.split()
        return os.environ.get("NEES_ONLY", source) not in source or os.environ.get("NEES_CUT", cut) != cut

    for name, xyz, up in sources():
        k = int(os.environ.get("NEES_PARTS", "4"))
        scenarios.append((f"{name} shares", lambda rng, xyz=xyz, k=k: shares(rng, xyz, k), up))
        if name != "3dtk-scan001":  # its scans leave out the quarter behind the robot
            scenarios.append((f"{name} wedges", lambda rng, xyz=xyz, up=up: wedges(xyz, up, 4, 150.0, rng.uniform(0, 360)), up))
    with tempfile.TemporaryDirectory() as d:
        for label, cut, up in scenarios:
            results = {m: [] for m in modes}
            joint = {m: [] for m in modes}
            # (mode, what) → each trial's joint NEES and part count.
            variants = {}
            exits = {m: [] for m in modes}
            silent = {m: 0 for m in modes}
            # mode → each trial's z² along its joint covariance's eigendirections.
            eigen = {}
            for trial in range(trials):
                parts = cut(rng)
                truths = [np.eye(4)] + [random_pose(rng, up, 45, 2, 0.5) for _ in parts[1:]]
                starts = [np.eye(4)] + [random_pose(rng, up, 2, 2, 0.1 / math.sqrt(3)) @ t for t in truths[1:]]
                # Another source or cut is drawn and not run: the draws stay the same.
                if skipped(label):
                    continue
                for mode in modes:
                    code, v = run(tool, d, parts, truths, starts, mode)
                    keep = os.environ.get("NEES_KEEP")
                    if keep:
                        import shutil
                        shutil.copytree(d, os.path.join(keep, f"{label.replace(' ', '-')}-{mode}-{trial}"),
                                        ignore=shutil.ignore_patterns("out"), dirs_exist_ok=True)
                        np.save(os.path.join(keep, f"{label.replace(' ', '-')}-{mode}-{trial}", "truths.npy"),
                                np.array(truths))
                    exits[mode].append(code)
                    if isinstance(v, str):
                        print(label, mode, "exit", code, v[:200])
                        continue
                    if os.environ.get("NEES_CHECKS"):
                        for c in v["checks"]:
                            a, b = c["target"], c["source"]
                            got = np.linalg.inv(np.array(v["scans"][a]["world_from_scan"])) @ np.array(v["scans"][b]["world_from_scan"])
                            e = xi(got, np.linalg.inv(truths[a]) @ truths[b])
                            print(f"  CHECK {label} {mode} {a}<-{b} rmse {c['rmse_m']} noise {c['noise_m']:.4f} "
                                  f"ratio {(c['rmse_m'] or 0) / c['noise_m']:.2f} gain {(c['start_rmse_m'] or 0) / (c['rmse_m'] or 1):.3f} "
                                  f"moved {c['moved_m']} "
                                  f"relative {c['relative_motion']} consistent {c['consistent']} exit {code} "
                                  f"err {np.linalg.norm(e[:3]) * 180 / math.pi:.3f}° {np.linalg.norm(e[3:]) * 1e3:.1f} mm")
                    # The trial's trusted parts together, against their joint covariance.
                    kept = [i for i in range(1, len(parts)) if i not in v.get("untrusted", [])]
                    if kept and v.get("joint_covariance") is not None:
                        big = np.array(v["joint_covariance"])
                        rows_ = np.concatenate([np.arange(6 * i, 6 * i + 6) for i in kept])
                        e = np.concatenate([xi(np.array(v["scans"][i]["world_from_scan"]), truths[i]) for i in kept])
                        joint[mode].append((e @ np.linalg.solve(big[np.ix_(rows_, rows_)], e), len(kept)))
                        if os.environ.get("NEES_EIG") and len(kept) == len(parts) - 1:
                            lam, vec = np.linalg.eigh(big[np.ix_(rows_, rows_)])
                            # Each eigendirection's z², and its share that turns the parts.
                            turns = (vec.reshape(len(kept), 6, -1)[:, :3, :] ** 2).sum(axis=(0, 1))
                            eigen.setdefault(mode, []).append(((vec.T @ e) ** 2 / lam, turns))
                        scales = os.environ.get("NEES_DEPARTURE_SCALES")
                        if scales and v["scans"][kept[0]].get("departure") is not None:
                            # The reported joint covariance is the adjustment's plus ξξᵀ.
                            dep = np.concatenate([np.array(v["scans"][i]["departure"]) for i in kept])
                            adjustment = big[np.ix_(rows_, rows_)] - np.outer(dep, dep)
                            for c in map(float, scales.split(",")):
                                nees = e @ np.linalg.solve(adjustment + c * np.outer(dep, dep), e)
                                variants.setdefault((mode, f"departure's ξξᵀ × {c}:"), []).append((nees, len(kept)))
                            own = (e - dep) @ np.linalg.solve(adjustment, e - dep)
                            variants.setdefault((mode, "the adjustment's own error:"), []).append((own, len(kept)))
                    for i in range(1, len(parts)):
                        e = xi(np.array(v["scans"][i]["world_from_scan"]), truths[i])
                        c = np.array(v["scans"][i]["covariance"])
                        results[mode].append((e, c, i in v.get("untrusted", [])))
                        wrong = np.linalg.norm(e[:3]) > math.radians(1) or np.linalg.norm(e[3:]) > 0.1
                        silent[mode] += wrong and code == 0
                        if os.environ.get("NEES_VERBOSE"):
                            print(f"  {label} {mode} part {i}: exit {code}, {np.linalg.norm(e[:3]) * 180 / math.pi:.3f}° "
                                  f"{np.linalg.norm(e[3:]) * 1e3:.1f} mm, NEES {e @ np.linalg.solve(c, e):.1f}, "
                                  f"untrusted {i in v.get('untrusted', [])}{departure(v['scans'][i])}")
            for mode in modes:
                if skipped(label):
                    continue
                rows = [r for r in results[mode] if not r[2]]
                if not rows:
                    print(f"{label:28} {mode:12} no trusted result; exits {exits[mode]}")
                    continue
                nees = np.array([e @ np.linalg.solve(c, e) for e, c, _ in rows])
                rot = np.array([e[:3] @ np.linalg.solve(c[:3, :3], e[:3]) for e, c, _ in rows])
                tra = np.array([e[3:] @ np.linalg.solve(c[3:, 3:], e[3:]) for e, c, _ in rows])
                n = len(rows)
                lo, hi = chi2_interval(6 * n)
                deg = np.sqrt(np.mean([np.sum(e[:3] ** 2) for e, _, _ in rows])) * 180 / math.pi
                mm = np.sqrt(np.mean([np.sum(e[3:] ** 2) for e, _, _ in rows])) * 1e3
                sdeg = np.sqrt(np.mean([np.trace(c[:3, :3]) for _, c, _ in rows])) * 180 / math.pi
                smm = np.sqrt(np.mean([np.trace(c[3:, 3:]) for _, c, _ in rows])) * 1e3
                print(f"{label:28} {mode:12} n={n:3} NEES mean {nees.mean():8.2f} [{lo / n:.2f}, {hi / n:.2f}] "
                      f"median {np.median(nees):7.2f} rot {rot.mean():7.2f} tra {tra.mean():7.2f} | "
                      f"error {deg:.4f}° {mm:.2f} mm, σ {sdeg:.4f}° {smm:.2f} mm; untrusted "
                      f"{sum(r[2] for r in results[mode])}, exits {sorted(set(exits[mode]))}, "
                      f"off > 1° or 0.1 m with exit 0: {silent[mode]}")
                if joint[mode]:
                    # The parts of one trial share links, so their NEES are
                    # not independent and the interval above holds only for
                    # independent parts; the trials are independent: each
                    # trial's parts against their joint covariance (χ² with
                    # 6 per part when honest), per part.
                    total, poses = per_part(joint[mode])
                    jlo, jhi = chi2_interval(6 * poses)
                    print(f"{'':41} joint NEES per part {total / poses:8.2f} [{jlo / poses:.2f}, {jhi / poses:.2f}] "
                          f"over {len(joint[mode])} trials")
                for (m, what), nees in variants.items():
                    if m == mode:
                        total, poses = per_part(nees)
                        print(f"{'':41} {what:32} joint NEES per part {total / poses:8.2f}")
                if eigen.get(mode):
                    # Smallest variance first: the errors' z² along each, and how much of each is a turn.
                    z2 = np.mean([z for z, _ in eigen[mode]], axis=0)
                    turns = np.mean([r for _, r in eigen[mode]], axis=0)
                    print(f"{'':41} along the joint covariance's eigendirections, z²: " + " ".join(f"{x:.2f}" for x in z2))
                    print(f"{'':41} their share that turns the parts:           " + " ".join(f"{x:.2f}" for x in turns))
                if os.environ.get("NEES_AXES"):
                    # Per axis of the world (ω x y z, v x y z): the errors' mean square over the reported variance.
                    ratio = [np.mean([e[k] ** 2 for e, _, _ in rows]) / np.mean([c[k, k] for _, c, _ in rows]) for k in range(6)]
                    print(f"{'':41} per axis, error² / variance: " + " ".join(f"{r:.2f}" for r in ratio))
                sys.stdout.flush()


def per_part(trials):
    """The trials' joint NEES summed, and their parts counted: [(NEES, parts)] → (Σ NEES, Σ parts)."""
    return sum(j for j, _ in trials), sum(k for _, k in trials)


def chi2_interval(dof):
    # Wilson–Hilferty: good to a fraction of a percent at these dof.
    z = 1.959964
    f = lambda s: dof * (1 - 2 / (9 * dof) + s * z * math.sqrt(2 / (9 * dof))) ** 3  # noqa: E731
    return f(-1), f(1)


if __name__ == "__main__":
    main()
