#!/usr/bin/env bash
# The free-space test's shares (fusion::free_space) on right and wrong
# registrations: every checked pair's violations / (violations +
# agreements), per case, with match's exit code and untrusted scans.
#
#   cargo build --release -p missions && PYTHON=target/ci-venv/bin/python bash fusion/benches/free_space_shares.sh
#
# Right: the 3DTK set, the PCL room pair, the simulated hall's and
# corridor's scans. Wrong: a scan of another place among a set, and
# scan000 + scan002 of the 3DTK set alone (they slide onto each other).
# Then the same real scans as plain PLY (no viewpoint: each scanner's
# position estimated from its scan's spacing, fusion::viewpoint), started
# where their own registration put them, with small_gicp's pair, a scan
# merged from two stations, the 3DTK set thinned to 2 and 5 cm cells (a
# thinned room scan among the 2 cm ones), and the 3DTK scan000 among
# small_gicp's frames
# (numpy and plyfile for the conversion, as fusion/benches/global_success.py:
# PYTHON=target/ci-venv/bin/python, the venv .ci/run makes).
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
bin=${CPS_SURVEY:-$root/target/release/cps-survey}
data=$root/data
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

shares() { # name, match arguments…
    local name=$1
    shift
    local rc=0
    "$bin" match "$@" --out "$work/$name" --json >"$work/$name.json" 2>/dev/null || rc=$?
    python3 - "$name" "$rc" "$work/$name.json" <<'PY'
import json, sys
name, rc, path = sys.argv[1], sys.argv[2], sys.argv[3]
r = json.load(open(path))
s = sorted((c["free_space"]["share"], c["source"], c["target"]) for c in r["checks"] if c["free_space"])
names = [x["name"] for x in r["scans"]]
pairs = " ".join(f"{names[a]}/{names[b]} {100 * v:.1f}%" for v, a, b in s)
print(f"{name:<22} exit {rc}  untrusted {[names[i] for i in r['untrusted']]}  pairs {len(s)}  "
      f"max {100 * s[-1][0] if s else float('nan'):.1f}%  check {r['check_seconds']:.2f} s")
if len(s) <= 6:
    print(f"{'':<22} {pairs}")
PY
}

sim() { # example, run name, edits as python replace pairs…
    local example=$1 dir=$work/$2
    mkdir -p "$dir"
    python3 - "$root/missions/examples/$example" "$dir/m.toml" <<'PY'
import sys
s = open(sys.argv[1]).read()
for a, b in [('mode = "icp"', 'mode = "direct"'), ("max_station_error_m = 0.25", "max_station_error_m = 100.0")]:
    s = s.replace(a, b)
open(sys.argv[2], "w").write(s.replace("[output]", "[output]\nrerun = false"))
PY
    (cd "$dir" && "$bin" run m.toml --quiet >/dev/null)
    echo "$dir/runs"/*/scans
}

room=$data/pcl_room_scans
dtk=$data/3dtk_dat
shares 3dtk-set "$dtk"
shares room-pair "$room/room_scan1.pcd" "$room/room_scan2.pcd"
hall_scans=$(sim hall.toml hall)
corridor_scans=$(sim corridor-icp.toml corridor)
shares hall-sim "$hall_scans"
shares corridor-sim "$corridor_scans"
shares hall000-among-rooms "$room/room_scan1.pcd" "$room/room_scan2.pcd" "$dtk/scan000.3d"
shares hall001-among-rooms "$room/room_scan1.pcd" "$room/room_scan2.pcd" "$dtk/scan001.3d"
shares room1-among-3dtk "$dtk/scan000.3d" "$dtk/scan001.3d" "$room/room_scan1.pcd"
shares room2-among-3dtk "$dtk/scan000.3d" "$dtk/scan001.3d" "$dtk/scan002.3d" "$room/room_scan2.pcd"
shares street-among-3dtk "$dtk/scan000.3d" "$dtk/scan001.3d" "$data/small_gicp_pair/source.ply"
mkdir -p "$work/s02" && cp "$dtk"/scan00[02].* "$work/s02/"
shares 3dtk-000-002-alone "$work/s02"

# The same scans as plain PLY: the viewpoints estimated.
ply=$work/ply
mkdir -p "$ply"
"$bin" match "$dtk" --out "$work/ref3" --json >"$work/ref3.json" 2>/dev/null || true
"$bin" match "$room/room_scan1.pcd" "$room/room_scan2.pcd" --out "$work/refr" --json >"$work/refr.json" 2>/dev/null || true
"${PYTHON:-python3}" - "$root/fusion/benches" "$data" "$ply" "$work/ref3.json" "$work/refr.json" \
    "$hall_scans" "$work/hall-sim.json" "$corridor_scans" "$work/corridor-sim.json" <<'PY'
import json, os, sys
import numpy as np
sys.path.insert(0, sys.argv[1])
from global_success import read_pcd, write_ply
data, out, ref3, refr, hall, hall_ref, corridor, corridor_ref = sys.argv[2:]
def dtk(name):  # 3DTK's left-handed cm → ours (z, −x, y) / 100, as scanner::io
    a = np.loadtxt(os.path.join(data, "3dtk_dat", name + ".3d"), usecols=(0, 1, 2))
    return np.stack([a[:, 2], -a[:, 0], a[:, 1]], 1) / 100.0
def dtk_dir(d, out, ref):  # a simulated run's scans as PLY, started where match put them
    r = json.load(open(ref))
    os.makedirs(out, exist_ok=True)
    for sc in r["scans"]:
        a = np.loadtxt(os.path.join(d, sc["name"] + ".3d"), usecols=(0, 1, 2))
        write_ply(os.path.join(out, sc["name"] + ".ply"), np.stack([a[:, 2], -a[:, 0], a[:, 1]], 1) / 100.0)
    json.dump([{"file": sc["name"] + ".ply", "world_from_scan": sc["world_from_scan"]} for sc in r["scans"]],
              open(os.path.join(out, "init.json"), "w"))
def init(path, names, ref):
    poses = [s["world_from_scan"] for s in json.load(open(ref))["scans"]]
    json.dump([{"file": n + ".ply", "world_from_scan": p} for n, p in zip(names, poses)], open(path, "w"))
scans = {n: dtk(n) for n in ["scan000", "scan001", "scan002"]}
for n, xyz in scans.items():
    write_ply(os.path.join(out, n + ".ply"), xyz)
rooms = {n: read_pcd(os.path.join(data, "pcl_room_scans", n + ".pcd")) for n in ["room_scan1", "room_scan2"]}
for n, xyz in rooms.items():
    write_ply(os.path.join(out, n + ".ply"), xyz)
init(os.path.join(out, "init3.json"), list(scans), ref3)
init(os.path.join(out, "initr.json"), ["room_scan1", "room_scan2"], refr)
poses = [np.array(s["world_from_scan"]) for s in json.load(open(ref3))["scans"]]
t = np.linalg.inv(poses[0]) @ poses[1]
write_ply(os.path.join(out, "merged01.ply"), np.vstack([scans["scan000"], scans["scan001"] @ t[:3, :3].T + t[:3, 3]]))
json.dump([{"file": "merged01.ply", "world_from_scan": poses[0].tolist()},
           {"file": "scan002.ply", "world_from_scan": poses[2].tolist()}], open(os.path.join(out, "initm.json"), "w"))
for cell in (0.02, 0.05):  # the set thinned on a grid, one point per cell
    d = os.path.join(out, f"thinned{round(cell * 100)}")
    os.makedirs(d, exist_ok=True)
    for n, xyz in {**scans, **rooms}.items():
        keep = np.unique(np.floor(xyz / cell).astype(np.int64), axis=0, return_index=True)[1]
        write_ply(os.path.join(d, n + ".ply"), xyz[np.sort(keep)])
    init(os.path.join(d, "init3.json"), list(scans), ref3)
dtk_dir(hall, os.path.join(out, "hall"), hall_ref)
dtk_dir(corridor, os.path.join(out, "corridor"), corridor_ref)
PY
cp "$data/small_gicp_pair/target.ply" "$data/small_gicp_pair/source.ply" "$ply/"
viewpoints() { # a run's estimated viewpoints: the share of the spacing they explain
    python3 - "$work/$1.json" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
e = [(s["name"], s["viewpoint"]) for s in r["scans"] if s["viewpoint"]]
if len(e) > 6:
    x = [v["explained"] for _, v in e]
    print(" " * 22, f"{sum(v['used'] for _, v in e)} of {len(e)} used, explaining {min(x):.2f}–{max(x):.2f}")
else:
    print(" " * 22, "  ".join(f"{n} {v['explained']:.2f}" + ("" if v["used"] else " unused") for n, v in e))
PY
}
shares ply-3dtk-set "$ply"/scan00[012].ply --init-poses "$ply/init3.json"; viewpoints ply-3dtk-set
shares ply-room-pair "$ply/room_scan1.ply" "$ply/room_scan2.ply" --init-poses "$ply/initr.json"; viewpoints ply-room-pair
shares ply-street-pair "$ply/target.ply" "$ply/source.ply"; viewpoints ply-street-pair
shares ply-hall-sim "$ply"/hall/*.ply --init-poses "$ply/hall/init.json"; viewpoints ply-hall-sim
shares ply-corridor-sim "$ply"/corridor/*.ply --init-poses "$ply/corridor/init.json"; viewpoints ply-corridor-sim
shares ply-3dtk-thinned-2cm "$ply"/thinned2/scan00[012].ply --init-poses "$ply/thinned2/init3.json"; viewpoints ply-3dtk-thinned-2cm
shares ply-3dtk-thinned-5cm "$ply"/thinned5/scan00[012].ply --init-poses "$ply/thinned5/init3.json"; viewpoints ply-3dtk-thinned-5cm
shares ply-merged-and-002 "$ply/merged01.ply" "$ply/scan002.ply" --init-poses "$ply/initm.json"; viewpoints ply-merged-and-002
shares ply-hall-among-rooms "$ply/room_scan1.ply" "$ply/room_scan2.ply" "$ply/scan000.ply"
shares ply-room1-among-3dtk "$ply"/scan00[012].ply "$ply/room_scan1.ply"
shares ply-street-among-3dtk "$ply"/scan00[012].ply "$ply/target.ply"
shares ply-room1-among-thinned-2cm "$ply"/thinned2/scan00[012].ply "$ply/thinned2/room_scan1.ply"
shares ply-hall-among-street "$ply/target.ply" "$ply/source.ply" "$ply/scan000.ply"
