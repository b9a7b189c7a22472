#!/usr/bin/env bash
# Runs production scenes of launch/production/ side by side on one GPU under the CUDA
# Multi-Process Service, each continuing from its last checkpoint, for at most LIMIT seconds,
# then analyses those that reached their end (docs/production.md: "GPU cost of small scenes").
#
#   LIMIT=540 OUT=results bash launch/production/run_on_gpu.sh dodecahedra_cylinder_x10 drum_speeds fixed_bed
#
# Run it again to continue: a run stopped by the limit writes checkpoints/latest.ckpt (SIGINT)
# and the next call restarts from it. POLYDEM (default target/release/polydem) is the binary;
# PRECISION the GPU precision (default mixed; double for the silo scenes); THREADS the host
# threads per run (default: the cores shared out). Results (summaries, analyses, plots) go to
# OUT (default launch/production/out/results).
set -uo pipefail
here=$(cd "$(dirname "$0")" && pwd)
bin=${POLYDEM:-$here/../../target/release/polydem}
out=${OUT:-$here/out/results}
limit=${LIMIT:-540}
scenes=("$@")
[ ${#scenes[@]} -gt 0 ] || { echo "usage: $0 SCENE ... (names of launch/production/*.toml)" >&2; exit 2; }
mkdir -p "$out"
export RAYON_NUM_THREADS=${THREADS:-$(( ($(nproc) + ${#scenes[@]} - 1) / ${#scenes[@]} ))}
mps=0
if command -v nvidia-cuda-mps-control > /dev/null && [ ${#scenes[@]} -gt 1 ]; then
  nvidia-cuda-mps-control -d && mps=1
fi
# The discharges start from the fill's final state, kept there once the fill has run; unpacked
# once, here, not by each discharge: parallel unpacks into one file let a run read it half written.
fin=$here/out/silo_quarter_fill/final.ckpt
if [[ " ${scenes[*]}" == *" silo_discharge_"* ]] && [ ! -f "$fin" ] && [ -f "$here/restart/silo_quarter_fill.final.ckpt.gz" ]; then
  mkdir -p "$(dirname "$fin")" && gunzip -c "$here/restart/silo_quarter_fill.final.ckpt.gz" > "$fin.part" && mv "$fin.part" "$fin"
fi
for s in "${scenes[@]}"; do
  (
    dir=$here/out/$s
    if [ -f "$dir/summary.json" ] && grep -q '"interrupted": false' "$dir/summary.json"; then
      echo "$s: finished before"; exit 0
    fi
    # A run carried over from an earlier sitting (launch/production/restart/, README there).
    if [ ! -f "$dir/checkpoints/latest.ckpt" ] && [ -f "$here/restart/$s.ckpt.gz" ]; then
      mkdir -p "$dir/checkpoints" && gunzip -c "$here/restart/$s.ckpt.gz" > "$dir/checkpoints/latest.ckpt"
    fi
    if [ -f "$dir/checkpoints/latest.ckpt" ]; then args=(--restart "$dir/checkpoints/latest.ckpt"); else args=(--overwrite); fi
    # The silo's mineral grains run faster in double: mixed precision's hull check sends many of
    # their face-on-face pairs to f64 after f32 (docs/production.md, case 4b).
    if [[ $s == silo_* ]]; then prec=${PRECISION:-double}; else prec=${PRECISION:-mixed}; fi
    start=$(date +%s)
    timeout -s INT "$limit" "$bin" run "$here/$s.toml" --backend cuda --gpu-precision "$prec" \
      "${args[@]}" >> "$out/$s.log" 2>&1
    echo "$s: rc $? after $(( $(date +%s) - start )) s (${args[*]})"
  ) &
done
wait
[ $mps = 1 ] && echo quit | nvidia-cuda-mps-control
# The analyses of the runs that reached their end.
done_() { [ -f "$here/out/$1/summary.json" ] && grep -q '"interrupted": false' "$here/out/$1/summary.json"; }
last_ckpt() { ls "$here/out/$1/checkpoints/"step_*.ckpt 2>/dev/null | sort | tail -1; }
for s in "${scenes[@]}"; do
  done_ "$s" || continue
  cp "$here/out/$s/summary.json" "$out/$s.summary.json"
  case $s in
    dodecahedra_cylinder_x10)
      ck=$(last_ckpt "$s")
      for k in 0 1 2 3 4 5 6 7 8 9; do
        x=$(python3 -c "print(0.12 * ($k % 5))"); y=$(python3 -c "print(0.12 * ($k // 5))")
        "$bin" analyze fill-height "$here/$s.toml" "$ck" --radius 0.05 --centre "$x,$y" > "$out/pour_$k.json"
      done ;;
    drum_speeds)
      for k in 0 1 2; do
        y=$(python3 -c "print(0.03 * ($k - 1))")
        "$bin" analyze drum "$here/out/$s/particles" --radius 0.15 --centre 0,0 \
          --y="$(python3 -c "print($y - 0.0055)"),$(python3 -c "print($y + 0.0055)")" --from 2 --cell 0.005 \
          --field "$out/drum_$k.csv" > "$out/drum_$k.json"
      done
      python3 "$here/drum_field.py" "$out/drum_speeds.svg" "30 rpm:$out/drum_0.csv:$out/drum_0.json" \
        "45 rpm:$out/drum_1.csv:$out/drum_1.json" "60 rpm:$out/drum_2.csv:$out/drum_2.json" ;;
    fixed_bed)
      ck=$(last_ckpt "$s")
      "$bin" analyze fill-height "$here/$s.toml" "$ck" --radius 0.0125 > "$out/fixed_bed_fill.json"
      top=$(python3 -c "import json; print(json.load(open('$out/fixed_bed_fill.json'))['mean_surface'] - 0.0055)")
      "$bin" analyze porosity "$here/$s.toml" "$ck" --radius 0.0125 --z "0.0055,$top" --annuli 50 \
        > "$out/fixed_bed_porosity.json"
      python3 "$here/bed_porosity.py" "$out/fixed_bed_porosity.svg" "$out/fixed_bed_porosity.json" \
        > "$out/fixed_bed_porosity.txt" ;;
    silo_grain_heap)
      "$bin" analyze heap "$here/$s.toml" "$(last_ckpt "$s")" --radius 0.2 --floor 0 --fit 0.5,0.95 \
        > "$out/silo_grain_heap.json"
      python3 "$here/heap_profile.py" "$out/silo_grain_heap.svg" "$out/silo_grain_heap.json" \
        > "$out/silo_grain_heap.txt" ;;
    silo_quarter_fill)
      ck=$(last_ckpt "$s")
      # The discharge scenes start from this state: their grain count (those below the cut)
      # is known now (the count error of `polydem check` gives it).
      cp "$ck" "$here/out/$s/final.ckpt"
      n=$("$bin" check "$here/silo_discharge_75mm.toml" 2>&1 | grep -o '[0-9]* of the [0-9]* particles' | head -1 | cut -d' ' -f1)
      if [ -n "$n" ]; then
        python3 "$here/make_scenes.py" --discharge-count "$n" \
          $(python3 "$here/make_scenes.py" --discharge-outlets | cut -d' ' -f1)
      fi
      "$bin" analyze fill-height "$here/$s.toml" "$ck" --radius 0.25 > "$out/silo_fill.json"
      "$bin" analyze heap "$here/$s.toml" "$ck" --radius 0.25 > "$out/silo_heap.json"
      # Hopper top 0.3096 m; the side's bands are 9 pitches of 43.5 mm; the packing fraction
      # from the porosity of the cylinder between the hopper and a grain below the surface.
      top=$(python3 -c "import json; print(json.load(open('$out/silo_fill.json'))['mean_surface'])")
      "$bin" analyze porosity "$here/$s.toml" "$ck" --radius 0.254 --z "0.35,$(python3 -c "print($top - 0.033)")" \
        --annuli 20 > "$out/silo_porosity.json"
      rho_b=$(python3 -c "import json; print(2500 * (1 - json.load(open('$out/silo_porosity.json'))['mean']))")
      python3 "$here/silo_janssen.py" "$here/out/$s/series.csv" "$out/silo_janssen.svg" --radius 0.2625 \
        --hopper-top 0.3096 --band-height 0.3915 --fill-top "$top" --bulk-density "$rho_b" \
        --from "$(python3 -c "import json; print(json.load(open('$here/out/$s/summary.json'))['simulated_time'] - 0.5)")" \
        > "$out/silo_janssen.txt" ;;
  esac
done
# Case 5: every discharge that reached its end, against Beverloo's law (grain 3.42e-6 m³ of
# 2500 kg/m³, d = 18.7 mm volume-equivalent). Each outlet's diameter and the height its grains
# are counted out at (above the cut for the cut hopper) come from make_scenes.py, which wrote
# the scenes.
runs=()
while read -r s d0 z; do
  done_ "$s" || continue
  runs+=("$d0@$z:$here/out/$s/particles")
  # The counts alone ("time grains" lines), which silo_discharge.py also reads: they join runs
  # of other sittings, whose particle tables are gone, in one fit.
  python3 -c "import sys; sys.path.insert(0, '$here'); import silo_discharge as s
for t, n in s.counts('$here/out/$s/particles', $z): print(t, n)" > "$out/$s.counts"
done < <(python3 "$here/make_scenes.py" --discharge-outlets)
# The bulk density from the fill's porosity: this sitting's, else the fill's recorded run.
porosity=$out/silo_porosity.json
[ -f "$porosity" ] || porosity=$here/../../docs/data/production_silo_quarter_fill_h200.json
if [ ${#runs[@]} -ge 2 ] && [ -f "$porosity" ]; then
  rho_b=$(python3 -c "import json; j = json.load(open('$porosity')); j = j['porosity'] if 'fill' in j else j; print(2500 * (1 - j['mean']))")
  # The law fitted to the orifice plates (4-8 d: a flat bottom under the hopper), the hopper's
  # open outlets (9 and 10 d) set against it; and fitted to all.
  for fit in 0.16:plates inf:all; do
    python3 "$here/silo_discharge.py" "$out/silo_discharge_${fit#*:}.svg" "${runs[@]}" --grain-mass 8.546e-3 \
      --bulk-density "$rho_b" --d 0.0187 --window auto --fit-max "${fit%%:*}" \
      > "$out/silo_discharge_${fit#*:}.txt"
  done
fi
ls -la "$out"
