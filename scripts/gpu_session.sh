#!/usr/bin/env bash
# The GPU checks and A/B benches of the work that waits for a GPU, in one or two device calls.
#
# Here (no GPU):  bash scripts/gpu-pack.sh --test gpu_pipeline --test mpi_decomposition \
#                     --test neighbor_modes --test mixed_flat_contacts --test cuda_geometry_host \
#                     --test validation_contact --test bench_packings
# There, from the repository root with .device/ carried:
#   bash scripts/gpu_session.sh tests     # the GPU tests, several processes at once (~5-8 min)
#   bash scripts/gpu_session.sh benches   # the A/B benches, one at a time on an idle GPU
#   bash scripts/gpu_session.sh all       # both
#   bash scripts/gpu_session.sh settled   # docs/performance.md's settled packings, and what the
#                                         # face trajectory (the default) costs them
#   bash scripts/gpu_session.sh enum      # the many-faced settled packings with the enumeration
#                                         # taking up to 8, 12 and 16 planes (POLYDEM_ENUM_PLANES)
#   bash scripts/gpu_session.sh regress   # the settled many-faced packings with this CLI and each
#                                         # .device/bin/polydem_<name> (scripts/pack-commit.sh),
#                                         # alternating, then this CLI's phase clocks
#   ONLY="gpu_pipeline validation_friction" bash scripts/gpu_session.sh tests   # some groups
# Results go to $OUT (the device call's folder; out/gpu_session here): summary.txt (one line a
# test or bench), logs.tgz (every log, each line stamped with the seconds since its test began)
# and benches.jsonl (every bench report, tagged).
#
# The A/B pairs run the same binary with and without one setting, alternating, twice each:
# - POLYDEM_GPU_EXCHANGE=host against device: a decomposed GPU run's rebuilds through the host
#   or on the device (docs/parallel.md), on 2 ranks of launch/neighbor/spheres_dense.toml;
# - POLYDEM_PAIR_BATCH=2147483647 (every candidate staged at once) against the default batches:
#   device bytes per particle and speed, 1e6 settled dodecahedra, mixed precision;
# - POLYDEM_MIXED_LP=f32 against the default f64 LP: the same scene's speed (docs/performance.md,
#   "Mixed precision and dense dodecahedra").
set -u
cd "$(dirname "$0")/.."
what=${1:-all}
OUT=${OUT:-out/gpu_session}
mkdir -p "$OUT"
logs=$(mktemp -d)
summary="$OUT/summary.txt"
: > "$summary"
export POLYDEM_ROOT=$PWD PATH=$PWD/.device/bin:$PATH
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
T=.device/tests
[ -x .device/bin/polydem ] || { echo "no .device/bin/polydem: run scripts/gpu-pack.sh here first" >&2; exit 2; }
nvidia-smi --query-gpu=name,memory.total --format=csv,noheader >> "$summary" 2>&1

# name|command: the GPU tests of the open work. The MPI tests start 2-3 ranks each.
tests=(
  "gpu_pipeline|$T/gpu_pipeline --ignored --test-threads 3"
  "gpu_rounded|$T/gpu_pipeline --ignored --exact rounded_grains_on_the_gpu_are_bitwise_the_cpu"
  "gpu_rolling|$T/gpu_pipeline --ignored --exact rolling_friction_on_the_gpu_is_bitwise_the_cpu"
  "gpu_quickstart|$T/gpu_pipeline --ignored --exact the_quickstart_on_the_gpu_ends_bitwise_equal_to_the_cpu"
  "mpi_device_rebuild|$T/mpi_decomposition --ignored --exact gpu_rebuilds_on_the_device_are_the_host_round_trip"
  "mpi_gpu_ranks|$T/mpi_decomposition --ignored --exact gpu_ranks_match_one_gpu"
  "mpi_neighbor_modes|$T/mpi_decomposition --ignored --exact every_neighbor_mode_on_two_gpu_ranks_matches_one_gpu"
  "mpi_periodic_restart|$T/mpi_decomposition --ignored --exact gpu_ranks_periodic_grid_and_restart"
  "mpi_sheared|$T/mpi_decomposition --ignored --exact gpu_ranks_sheared_lattice_is_the_cpus"
  "mpi_stop|$T/mpi_decomposition --ignored --exact a_stop_on_one_gpu_rank_stops_every_rank_with_the_state_written"
  "neighbor_modes|$T/neighbor_modes --ignored"
  "mixed_flat_contacts|$T/mixed_flat_contacts --ignored"
  "cuda_geometry|$T/cuda_geometry_host --ignored"
  "validation_contact|$T/validation_contact --ignored --test-threads 2"
  "validation_friction|$T/validation_friction --ignored --test-threads 2"
  "validation_spheres|$T/validation_spheres --ignored --test-threads 2"
  "validation_moving_walls|$T/validation_moving_walls --ignored --test-threads 2"
  "vc_elastic_double|$T/validation_contact --ignored --exact elastic_collisions_on_gpu_double --nocapture"
  "vc_elastic_mixed|$T/validation_contact --ignored --exact elastic_collisions_on_gpu_mixed --nocapture"
  "vc_restitution_double|$T/validation_contact --ignored --exact restitution_on_gpu_double --nocapture"
  "vc_restitution_mixed|$T/validation_contact --ignored --exact restitution_on_gpu_mixed --nocapture"
  "vc_rest_double|$T/validation_contact --ignored --exact rest_on_gpu_double --nocapture"
  "vc_rest_mixed|$T/validation_contact --ignored --exact rest_on_gpu_mixed --nocapture"
  "vc_aligned_cubes|$T/validation_contact --ignored --exact aligned_cubes_on_gpu_double --nocapture"
  "vc_face_trajectory|$T/validation_contact --ignored --exact face_impacts_along_their_trajectory_on_gpu_double --nocapture"
  "vf_spheres_double|$T/validation_friction --ignored --exact friction_spheres_on_gpu_double --nocapture"
  "vf_spheres_mixed|$T/validation_friction --ignored --exact friction_spheres_on_gpu_mixed --nocapture"
  "vf_polyhedra_double|$T/validation_friction --ignored --exact friction_polyhedra_on_gpu_double --nocapture"
  "vf_polyhedra_mixed|$T/validation_friction --ignored --exact friction_polyhedra_on_gpu_mixed --nocapture"
  "vs_double|$T/validation_spheres --ignored --exact sphere_cases_on_gpu_double --nocapture"
  "vs_mixed|$T/validation_spheres --ignored --exact sphere_cases_on_gpu_mixed --nocapture"
  "vw_resting|$T/validation_moving_walls --ignored --exact resting_faces_at_the_default_step_on_gpu --nocapture"
  "vw_resting_mixed|$T/validation_moving_walls --ignored --exact resting_faces_at_the_default_step_on_gpu_mixed --nocapture"
  "vw_lattice|$T/validation_moving_walls --ignored --exact a_compressed_lattice_of_low_restitution_cubes_on_gpu_is_the_cpus --nocapture"
  "validation_impact|$T/validation_impact --ignored"
  "stability_guard|$T/stability --ignored --exact the_guard_stops_gpu_runs_at_the_same_steps"
  "scene_limits|$T/scene_limits --ignored"
  "gpu_minerals|$T/gpu_pipeline --ignored --exact settled_many_faced_grains_end_bitwise_equal_to_the_cpu"
  "pack_gpu|$T/bench_packings --ignored --exact compression_on_the_gpu_is_the_cpus --nocapture"
  "cuda_geometry_enum16|POLYDEM_ENUM_PLANES=16 $T/cuda_geometry_host --ignored --exact cuda_geometry_kernels_match_the_rust_reference_on_the_gpu"
)
# ONLY="name name ..." runs just those groups (the names before the '|').
if [ -n "${ONLY:-}" ]; then
  chosen=()
  for entry in "${tests[@]}"; do
    case " $ONLY " in *" ${entry%%|*} "*) chosen+=("$entry") ;; esac
  done
  tests=("${chosen[@]}")
fi

# Runs "name|command" lines, at most $2 at a time, each within $3 seconds.
run_parallel() {
  local -n list=$1
  local most=$2 limit=$3
  for entry in "${list[@]}"; do
    while [ "$(jobs -rp | wc -l)" -ge "$most" ]; do sleep 1; done
    (
      name=${entry%%|*}
      start=$(date +%s)
      # Each line stamped with the seconds since the test began: where the time goes.
      timeout "$limit" bash -c "${entry#*|}" 2>&1 | while IFS= read -r line; do
        printf -v now '%(%s)T' -1
        printf '%4d %s\n' "$((now - start))" "$line"
      done > "$logs/$name.log"
      rc=${PIPESTATUS[0]}
      printf '%-22s rc=%-3s %4ss  %s\n' "$name" "$rc" "$(($(date +%s) - start))" \
        "$(grep -E '^ *[0-9]+ test result' "$logs/$name.log" | tail -1)" >> "$summary"
    ) &
  done
  wait
}

bench() { # tag, environment, then the polydem bench arguments
  local tag=$1 env=$2
  shift 2
  local start=$(date +%s)
  env $env timeout 300 "$@" --json > "$logs/bench_$tag.json" 2> "$logs/bench_$tag.err"
  local rc=$?
  python3 - "$tag" "$env" "$logs/bench_$tag.json" "$OUT/benches.jsonl" << 'PY' >> "$summary"
import json, sys
tag, env, src, dst = sys.argv[1:]
try:
    r = json.load(open(src))
except Exception as e:
    print(f"bench {tag:<28} [{env}] no report ({e})"); sys.exit()
r["tag"], r["env"] = tag, env
open(dst, "a").write(json.dumps(r) + "\n")
par = r.get("parallel") or {}
print(f"bench {tag:<28} [{env}] {r['particle_steps_per_second']:.3e} ps/s, "
      f"{r.get('device_bytes_per_particle') or 0:.0f} B/particle, "
      f"pairs {r['stage_seconds']['pairs']:.3f} s, parallel {json.dumps(par)[:300]}")
PY
  echo "  (rc=$rc, $(($(date +%s) - start)) s)" >> "$summary"
}

if [ "$what" = tests ] || [ "$what" = all ]; then
  run_parallel tests "${PARALLEL:-6}" "${LIMIT:-540}"
fi
if [ "$what" = benches ] || [ "$what" = all ]; then
  mpi2="mpirun --oversubscribe -n 2 polydem bench"
  dense="launch/neighbor/spheres_dense.toml --backend cuda --neighbor-mode gpu --warmup 20 --steps 600"
  settled="launch/bench/settled/dodecahedra_1e6.toml --backend cuda --gpu-precision mixed --warmup 10 --steps 100"
  for round in 1 2; do
    bench "exchange_host_$round" POLYDEM_GPU_EXCHANGE=host $mpi2 $dense
    bench "exchange_device_$round" POLYDEM_GPU_EXCHANGE=device $mpi2 $dense
  done
  for round in 1 2; do
    bench "settled_default_$round" X=1 polydem bench $settled
    bench "settled_one_batch_$round" POLYDEM_PAIR_BATCH=2147483647 polydem bench $settled
    bench "settled_lp_f32_$round" POLYDEM_MIXED_LP=f32 polydem bench $settled
  done
fi
if [ "$what" = settled ]; then
  # The settled packings of docs/performance.md at 1e6 particles, one at a time on an idle GPU,
  # and the dodecahedra and mineral grains again with simulation.face_window = "secant" (the
  # default before the trajectory; a copy of the scene beside it, so that its packing path
  # still resolves): what the trajectory costs them.
  s=launch/bench/settled
  for name in dodecahedra mineral_grains cylinders; do
    sed 's/^\[simulation\]$/[simulation]\nface_window = "secant"/' "$s/${name}_1e6.toml" \
      > "$s/${name}_1e6_secant.toml"
  done
  steps="--warmup 10 --steps ${STEPS:-100}"
  bench dodecahedra_mixed X=1 polydem bench $s/dodecahedra_1e6.toml --backend cuda --gpu-precision mixed $steps
  bench dodecahedra_mixed_secant X=1 polydem bench $s/dodecahedra_1e6_secant.toml --backend cuda --gpu-precision mixed $steps
  bench dodecahedra_double X=1 polydem bench $s/dodecahedra_1e6.toml --backend cuda --gpu-precision double $steps
  bench dodecahedra_double_secant X=1 polydem bench $s/dodecahedra_1e6_secant.toml --backend cuda --gpu-precision double $steps
  bench mineral_grains_mixed X=1 polydem bench $s/mineral_grains_1e6.toml --backend cuda --gpu-precision mixed --warmup 5 --steps 40
  bench mineral_grains_mixed_secant X=1 polydem bench $s/mineral_grains_1e6_secant.toml --backend cuda --gpu-precision mixed --warmup 5 --steps 40
  bench cylinders_mixed X=1 polydem bench $s/cylinders_1e6.toml --backend cuda --gpu-precision mixed --warmup 5 --steps 40
  bench spheres_mixed X=1 polydem bench $s/spheres_1e6.toml --backend cuda --gpu-precision mixed $steps
fi
if [ "$what" = enum ]; then
  # The lean passes take every pair the enumeration can: with POLYDEM_ENUM_PLANES above 8 the
  # mineral grains' and cylinders' contacts of 9-16 planes (three quarters and four fifths,
  # docs/performance.md) stay out of the deferred pass. One binary, the setting alternated;
  # the dodecahedra (92 % at most 8 planes) as the control.
  s=launch/bench/settled
  short="--backend cuda --gpu-precision mixed --warmup 5 --steps 20"
  for round in $(seq "${ROUNDS:-1}"); do
    for n in 8 12 16; do
      for name in ${SCENES:-mineral_grains cylinders dodecahedra}; do
        bench "${name}_enum${n}_$round" POLYDEM_ENUM_PLANES=$n polydem bench $s/${name}_1e6.toml $short
      done
    done
  done
  [ "${DOUBLE:-1}" = 0 ] || for n in 8 16; do
    bench "mineral_grains_double_enum$n" POLYDEM_ENUM_PLANES=$n polydem bench \
      $s/mineral_grains_1e6.toml --backend cuda --gpu-precision double --warmup 5 --steps 20
  done
  # Where the pair time goes at each limit (per-phase thread-cycles in the .err logs).
  [ "${CLOCKS:-1}" = 0 ] || for n in 8 16; do
    bench "mineral_grains_enum${n}_clocks" "POLYDEM_ENUM_PLANES=$n POLYDEM_PHASE_CLOCKS=1" \
      polydem bench $s/mineral_grains_1e6.toml $short
  done
fi
if [ "$what" = regress ]; then
  # Where the many-faced shapes' pair stage went: this commit against older ones, one at a
  # time on an idle GPU, alternating, then POLYDEM_PHASE_CLOCKS=1 (per-phase thread-cycles of
  # the pair kernels in the .err logs) with each.
  s=launch/bench/settled
  # ROUNDS (default 1) alternations: about 1.5 min per CLI and round, so keep the CLIs times
  # ROUNDS within a call's 10 minutes. SCENES="mineral_grains" runs only some packings.
  short="--backend cuda --gpu-precision mixed --warmup 5 --steps 20"
  for round in $(seq "${ROUNDS:-1}"); do
    for cli in .device/bin/polydem*; do
      tag=$(basename "$cli")
      for name in ${SCENES:-mineral_grains cylinders dodecahedra}; do
        bench "${name}_${tag}_$round" X=1 "$cli" bench $s/${name}_1e6.toml $short
      done
    done
  done
  # CLOCKS=0 leaves the phase clocks out (a bisection needs only the speeds).
  [ "${CLOCKS:-1}" = 0 ] || for cli in .device/bin/polydem*; do
    bench "mineral_grains_$(basename "$cli")_clocks" POLYDEM_PHASE_CLOCKS=1 "$cli" bench \
      $s/mineral_grains_1e6.toml $short
  done
fi
tar -czf "$OUT/logs.tgz" -C "$logs" .
cat "$summary"
