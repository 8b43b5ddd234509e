#!/usr/bin/env bash
# A run's cost against its length (issue 35): paper-1km stretched to N
# stations (10 m strides, scans at every station), run, then adjusted on
# its own. Prints per N: wall time and peak memory of `run`, the journal's
# bytes per station, and `adjust`'s time with and without data snooping.
#
#   cargo build --release -p missions && bash missions/benches/run_scaling.sh 100 400 1600 4000
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
bin=$root/target/release/cps-survey
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
printf '%8s %10s %10s %12s %12s %14s\n' stations run_s peak_MB journal_B/st adjust_s adjust_nosnoop_s
for n in "${@:-100 400 1600}"; do
  sed -e "s/\[1000.0, 0.0, 0.0\]/[$((n * 10)).0, 0.0, 0.0]/" \
      -e 's/max_final_sigma_xy_m = 0.25/max_final_sigma_xy_m = 1000000.0/' \
      "$root/missions/examples/paper-1km.toml" > "$work/p$n.toml"
  /usr/bin/time -f '%e %M' -o "$work/time" "$bin" run "$work/p$n.toml" --out "$work/r$n" --quiet > /dev/null
  read -r run_s peak_kb < "$work/time"
  journal=$(stat -c %s "$work/r$n/journal.jsonl")
  /usr/bin/time -f '%e' -o "$work/adj" "$bin" adjust "$work/r$n" > /dev/null || true
  /usr/bin/time -f '%e' -o "$work/adj0" "$bin" adjust "$work/r$n" --no-snooping > /dev/null || true
  printf '%8d %10s %10d %12d %12s %14s\n' "$n" "$run_s" $((peak_kb / 1024)) $((journal / n)) "$(tail -1 "$work/adj")" "$(tail -1 "$work/adj0")"
  rm -rf "$work/r$n"
done
