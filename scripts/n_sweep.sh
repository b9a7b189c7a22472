#!/usr/bin/env bash
# Speed against size: GPU (mixed, and double for dodecahedra) and the CPU, one bench report per
# line into ${1:-sweep.jsonl}; then `python3 scripts/n_sweep.py plot sweep.jsonl sweep.svg`.
# BIN: the polydem binary (target/release/polydem); MAXN, CPU_MAXN: the largest sizes run.
cd "$(dirname "$0")/.."  # the repository root
export POLYDEM_ROOT=$PWD
B=$(dirname "${BIN:-target/release/polydem}")
log=${1:-sweep.jsonl}
# smallest first, both shapes, so that a run cut short still spans the sizes
python3 scripts/n_sweep.py scenes /tmp/sw | sort -k2 -n > /tmp/sw.list
MAXN=${MAXN:-9000000}
while read -r scene n; do
  [ "$n" -gt "$MAXN" ] && continue
  gs=$(python3 -c "print(max(10, min(3000, int(3e8 / $n))))")
  for p in mixed double; do
    case $scene in *spheres*) [ $p = double ] && continue;; esac
    r=$(timeout 120 $B/$(basename "${BIN:-polydem}") bench $scene --backend cuda --gpu-precision $p --warmup $(( gs / 5 + 5 )) --steps $gs 2>/dev/null | tr -d '\n')
    [ -n "$r" ] && echo "$r" >> $log
    echo "gpu $p $n: $(grep -o '"particle_steps_per_second": [0-9.e+]*' <<<"$r")"
  done
  if [ "$n" -le "${CPU_MAXN:-600000}" ]; then
    cs=$(python3 -c "print(max(4, min(2000, int(4e6 / $n))))")
    r=$(timeout 120 $B/$(basename "${BIN:-polydem}") bench $scene --backend cpu --warmup 3 --steps $cs 2>/dev/null | tr -d '\n')
    [ -n "$r" ] && echo "$r" >> $log
    echo "cpu $n: $(grep -o '"particle_steps_per_second": [0-9.e+]*' <<<"$r")"
  fi
done < /tmp/sw.list
