#!/usr/bin/env bash
# Regenerates the README's screenshots with the Rerun viewer, headless
# (software Vulkan):
#   docs/hall.png       the hall example's mission.rrd (a run);
#   docs/hall-plan.png  `plan hall-plan.toml --optimize --rrd` (the written
#                       plan with its violation, and the optimized plan).
# The viewer runs headless with its gRPC server on a private port; the
# screenshot is requested once the recording is loaded and the start-up
# notifications have gone (`--screenshot-to` takes it at start-up, under
# them).
# Needs: apt-get install mesa-vulkan-drivers; pip install "rerun-sdk==0.36.3".
set -euo pipefail
cd "$(dirname "$0")/.."
out="$(mktemp -d)"
port=9877
shot() { # shot RECORDING PNG
  env -u DISPLAY rerun --headless --window-size 1280x800 --bind 127.0.0.1 --port "$port" "$1" \
    >"$out/viewer.log" 2>&1 &
  local viewer=$!
  sleep 25
  python3 -c "from rerun.experimental import ViewerClient
ViewerClient('rerun+http://127.0.0.1:$port/proxy').save_screenshot('$PWD/$2')"
  sleep 5
  kill "$viewer" 2>/dev/null || true
  wait "$viewer" 2>/dev/null || true
  [ -s "$2" ] || { echo "no screenshot $2; the viewer said:"; cat "$out/viewer.log"; exit 1; }
}
rerun analytics disable >/dev/null 2>&1 || true
cargo run --release --locked -p missions -- run missions/examples/hall.toml --out "$out/hall" --quiet
shot "$out/hall/mission.rrd" docs/hall.png
# `plan` exits 1: the written plan breaks a constraint (that is the point).
cargo run --release --locked -p missions -- plan missions/examples/hall-plan.toml --optimize --rrd "$out/plan.rrd" \
  >/dev/null || [ $? -eq 1 ]
shot "$out/plan.rrd" docs/hall-plan.png
rm -rf "$out"
