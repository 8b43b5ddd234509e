#!/usr/bin/env bash
# Regenerates docs/hall.png: runs the hall example and takes a headless
# screenshot of its mission.rrd with the Rerun viewer (software Vulkan).
# Needs: apt-get install mesa-vulkan-drivers; pip install "rerun-sdk==0.36.3".
set -euo pipefail
cd "$(dirname "$0")/.."
out="$(mktemp -d)"
cargo run --release --locked -p missions -- run missions/examples/hall.toml --out "$out/hall" --quiet
env -u DISPLAY rerun --headless --window-size 1280x800 --screenshot-to docs/hall.png "$out/hall/mission.rrd"
rm -rf "$out"
