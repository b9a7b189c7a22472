#!/usr/bin/env bash
# Regenerates the settled random packings of launch/bench/packings/ with `polydem pack` (on the
# GPU when there is one) and the bench scenes that tile them (launch/bench/settled/,
# scripts/settled_benches.py). One compression at a time: several processes sharing one GPU
# time-slice it and each runs several times slower.
# Usage: scripts/make_packings.sh [path/to/polydem] [shape ...]
#   (default target/release/polydem and all four shapes)
set -euo pipefail
cd "$(dirname "$0")/.."
bin=${1:-target/release/polydem}
shift || true
shapes=("$@")
[ ${#shapes[@]} -eq 0 ] && shapes=(dodecahedra mineral_grains cylinders spheres)
declare -A contacts=([dodecahedra]=7 [mineral_grains]=7 [cylinders]=7 [spheres]=6.5)
for shape in "${shapes[@]}"; do
    dir=launch/bench/packings
    if ! "$bin" pack "$dir/$shape.toml" --contacts "${contacts[$shape]}" \
        --out "$dir/$shape.packing" > "$dir/$shape.json" 2> "$dir/$shape.log"; then
        tail -n 3 "$dir/$shape.log" >&2
        exit 1
    fi
    rm -f "$dir/$shape.log"
    echo "$shape: $(tr -d '\n ' < "$dir/$shape.json")"
done
python3 scripts/settled_benches.py
