#!/usr/bin/env sh
# The full benchmark run of docs/benchmarks.md: JSON to OUTDIR/bench.json, progress to OUTDIR/bench.log.
set -eu
out="${1:-benchmarks/results}"
mkdir -p "$out"
wmm-qp bench --json --ticks 20000 > "$out/bench.json" 2> "$out/bench.log"
echo "wrote $out/bench.json"
