#!/usr/bin/env bash
# Instructions per call of each model's fused `dynamics_terms` (M, N, J, J̇q̇; f64), counted
# by callgrind as the difference between 10 000 calls and 0 calls. Repeatable whatever
# else the machine is doing. Needs valgrind.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --quiet --release -p leg-tests --example fused_terms
bin=target/release/examples/fused_terms
count() { valgrind --tool=callgrind --callgrind-out-file=/dev/null "$bin" "$1" "$2" 2>&1 | sed -n 's/.*Collected : \([0-9]*\).*/\1/p'; }
n=10000
printf '%-18s %s\n' model instructions/call
for spec in leg-models/specs/*.toml; do
  m=$(basename "$spec" .toml)
  a=$(count "$m" 0); b=$(count "$m" $n)
  printf '%-18s %d\n' "$m" $(( (b - a) / n ))
done
