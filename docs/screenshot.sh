#!/usr/bin/env bash
# Regenerates the README's screenshots with the Rerun viewer, headless
# (software Vulkan):
#   docs/hall.png       the hall example's mission.rrd (a run);
#   docs/hall-plan.png  `plan hall-plan.toml --optimize --rrd` (the written
#                       plan with its violation, and the optimized plan).
# Needs: apt-get install mesa-vulkan-drivers; pip install "rerun-sdk==0.36.3".
set -euo pipefail
cd "$(dirname "$0")/.."
out="$(mktemp -d)"
cargo run --release --locked -p missions -- run missions/examples/hall.toml --out "$out/hall" --quiet
env -u DISPLAY rerun --headless --window-size 1280x800 --screenshot-to docs/hall.png "$out/hall/mission.rrd"
# `plan` exits 1: the written plan breaks a constraint (that is the point).
cargo run --release --locked -p missions -- plan missions/examples/hall-plan.toml --optimize --rrd "$out/plan.rrd" \
  >/dev/null || [ $? -eq 1 ]
env -u DISPLAY rerun --headless --window-size 1280x800 --screenshot-to docs/hall-plan.png "$out/plan.rrd"
rm -rf "$out"
