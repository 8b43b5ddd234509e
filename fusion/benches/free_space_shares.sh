#!/usr/bin/env bash
# The free-space test's shares (fusion::free_space) on right and wrong
# registrations: every checked pair's violations / (violations +
# agreements), per case, with match's exit code and untrusted scans.
#
#   cargo build --release -p missions && bash fusion/benches/free_space_shares.sh
#
# Right: the 3DTK set, the PCL room pair, small_gicp's pair (PLY: no
# viewpoint, so untested), the simulated hall's and corridor's scans.
# Wrong: a scan of another place among a set, and scan000 + scan002 of the
# 3DTK set alone (they slide onto each other).
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
shares hall-sim "$(sim hall.toml hall)"
shares corridor-sim "$(sim corridor-icp.toml corridor)"
shares hall000-among-rooms "$room/room_scan1.pcd" "$room/room_scan2.pcd" "$dtk/scan000.3d"
shares hall001-among-rooms "$room/room_scan1.pcd" "$room/room_scan2.pcd" "$dtk/scan001.3d"
shares room1-among-3dtk "$dtk/scan000.3d" "$dtk/scan001.3d" "$room/room_scan1.pcd"
shares room2-among-3dtk "$dtk/scan000.3d" "$dtk/scan001.3d" "$dtk/scan002.3d" "$room/room_scan2.pcd"
shares street-among-3dtk "$dtk/scan000.3d" "$dtk/scan001.3d" "$data/small_gicp_pair/source.ply"
mkdir -p "$work/s02" && cp "$dtk"/scan00[02].* "$work/s02/"
shares 3dtk-000-002-alone "$work/s02"
