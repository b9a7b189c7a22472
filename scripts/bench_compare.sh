#!/usr/bin/env bash
# Before/after figures for docs/performance.md: runs `polydem bench` on each scene with two
# binaries, alternating them (A B A B …) so that drift of the machine (clocks, temperature,
# other load) falls on both alike, and appends one JSON line per run to OUT.jsonl: the label
# (before/after), the round, and the bench report. scripts/bench_table.py makes the table.
#
# Usage: scripts/bench_compare.sh BEFORE_BIN AFTER_BIN OUT.jsonl ROUNDS "SCENE[:WARMUP:STEPS[:PRECISION]] …"
#   e.g. scripts/bench_compare.sh old/polydem target/release/polydem out.jsonl 2 \
#          "launch/bench/settled/dodecahedra_1e6.toml:10:50:mixed launch/bench/settled/spheres_1e6.toml:20:200"
# BENCH_ARGS adds arguments to every bench (e.g. "--backend cuda"); LAUNCH prefixes every run
# (e.g. "mpirun --oversubscribe -n 2"); BEFORE_ENV and AFTER_ENV set variables for one side
# (e.g. the same binary twice with BEFORE_ENV="POLYDEM_GPU_EXCHANGE=host"
# AFTER_ENV="POLYDEM_GPU_EXCHANGE=device").
set -euo pipefail
[ $# -eq 5 ] || { sed -n 2,10p "$0" >&2; exit 2; }
before=$1 after=$2 out=$3 rounds=$4 scenes=$5
for bin in "$before" "$after"; do
    [ -x "$bin" ] || { echo "$bin: not an executable" >&2; exit 2; }
done
for spec in $scenes; do
    IFS=: read -r scene warmup steps precision <<<"$spec"
    args=(--warmup "${warmup:-10}" --steps "${steps:-50}")
    [ -n "${precision:-}" ] && args+=(--gpu-precision "$precision")
    for round in $(seq 1 "$rounds"); do
        for label in before after; do
            bin=$before vars=${BEFORE_ENV:-}
            [ "$label" = after ] && bin=$after vars=${AFTER_ENV:-}
            # shellcheck disable=SC2086
            if report=$(env $vars ${LAUNCH:-} "$bin" bench "$scene" "${args[@]}" ${BENCH_ARGS:-} 2>/dev/null); then
                python3 -c 'import json,sys; r=json.loads(sys.argv[3]); print(json.dumps({"label": sys.argv[1], "round": int(sys.argv[2]), **r}))' \
                    "$label" "$round" "$report" >> "$out"
                echo "$label $round $scene: $(grep -o '"particle_steps_per_second": [0-9.e+]*' <<<"$report")"
            else
                echo "$label $round $scene: bench failed" >&2
                python3 -c 'import json,sys; print(json.dumps({"label": sys.argv[1], "round": int(sys.argv[2]), "scene": sys.argv[3], "failed": True}))' \
                    "$label" "$round" "$scene" >> "$out"
            fi
        done
    done
done
