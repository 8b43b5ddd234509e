"""Reads a mission.rrd with Rerun's Python reader (independent of our Rust
code) and checks the entities docs/recording.md promises, with their row counts
for the hall example (21 cycles, 2 children, 22 stations, a scan and a fix at each — the start is a resection on control)."""
import sys
from collections import defaultdict

from rerun.experimental import RrdReader

path = sys.argv[1]
rows = defaultdict(int)
for chunk in RrdReader(path).stream().to_chunks():
    rows[str(chunk.entity_path)] += chunk.num_rows

cycles, children, stations = 21, 2, 22
team = cycles * (children + 1) + 1
expected = {
    "/world/scene": 1,
    "/world/robots/parent": team,
    "/world/truth/ahead": team,
    "/world/uncertainty/behind/achieved_95pct": team,
    "/world/uncertainty/parent/predicted_95pct": team - 1,
    "/world/sight_lines/placement": cycles * children,
    "/world/sight_lines/fix": cycles,
    "/world/trajectories/parent/estimate": stations,
    "/world/scans/direct/scan021": 1,
    "/metrics/sigma_xy_m": stations,
    "/metrics/fix_sigma0_squared": stations,  # every cycle, and the start: a resection on control
    "/world/plan/route": 1,
    "/world/plan/sight_lines": 2 * cycles * children,
}
bad = {p: (rows.get(p), n) for p, n in expected.items() if rows.get(p) != n}
if bad:
    sys.exit(f"{path}: entity rows (found, expected) differ: {bad}; entities: {sorted(rows)}")
print(f"{path}: {len(rows)} entities, the {len(expected)} checked have the expected rows")
