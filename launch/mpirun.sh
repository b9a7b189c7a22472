#!/usr/bin/env bash
# Runs polydem on N MPI ranks of this machine: one rank per subdomain, the cores shared out
# between the ranks' rayon pools, each rank bound to its share of cores.
#
#   launch/mpirun.sh N SCENE [polydem run options...]
#   launch/mpirun.sh 4 launch/mpi/pour.toml --out out/pour4
#   POLYDEM_COMMAND=bench launch/mpirun.sh 2 launch/bench/dodecahedra_1e5.toml --steps 50
#
# Environment:
#   POLYDEM_BIN      the polydem binary (default: target/release/polydem, built if missing)
#   POLYDEM_COMMAND  run (default) or bench
#   MPIRUN           the launcher (default: mpirun)
#   MPIRUN_ARGS      extra launcher arguments (e.g. "--hostfile hosts")
#   RAYON_NUM_THREADS  threads per rank (default: cores / N, at least 1)
#   POLYDEM_BACKEND  cpu, cuda or auto (default)
#   POLYDEM_SIGKILL_TIMEOUT  seconds mpirun waits between SIGTERM and SIGKILL when interrupted
#                    (default 60: time for the interrupt checkpoint)
#
# On a GPU machine each rank drives the GPU of its node-local rank modulo the visible GPUs
# (docs/design.md §6); POLYDEM_BACKEND=cpu|cuda|auto (default auto) picks the backend.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if (($# < 2)); then
    sed -n '2,18p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'
    exit 2
fi
ranks="$1"
scene="$2"
shift 2
if ! [[ "$ranks" =~ ^[1-9][0-9]*$ ]]; then
    echo "mpirun.sh: N must be a positive integer, got '$ranks'" >&2
    exit 2
fi
if [[ ! -f "$scene" ]]; then
    echo "mpirun.sh: scene file '$scene' does not exist" >&2
    exit 2
fi
bin="${POLYDEM_BIN:-$ROOT/target/release/polydem}"
if [[ ! -x "$bin" ]]; then
    (cd "$ROOT" && cargo build --release --bin polydem)
fi
cores="$(nproc)"
threads="${RAYON_NUM_THREADS:-$(((cores / ranks) > 0 ? cores / ranks : 1))}"
export RAYON_NUM_THREADS="$threads"
launcher_args=(-n "$ranks" -x RAYON_NUM_THREADS)
if ((ranks * threads > cores)); then
    # More ranks × threads than cores (a laptop, CI): let Open MPI oversubscribe, bind nothing.
    launcher_args+=(--oversubscribe --bind-to none)
else
    launcher_args+=(--map-by "slot:PE=$threads" --bind-to core)
fi
# Ctrl-C or `kill` on mpirun: Open MPI sends every rank SIGTERM, then SIGKILL after
# odls_base_sigkill_timeout seconds (1 by default). The ranks agree on the signal after the
# step they are in and write the interrupt checkpoint; give them a minute for a large one.
launcher_args+=(--mca odls_base_sigkill_timeout "${POLYDEM_SIGKILL_TIMEOUT:-60}")
if [[ "$(id -u)" == 0 ]]; then
    # Open MPI refuses root without these (containers, CI).
    export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
fi
# shellcheck disable=SC2086
exec "${MPIRUN:-mpirun}" "${launcher_args[@]}" ${MPIRUN_ARGS:-} \
    "$bin" "${POLYDEM_COMMAND:-run}" "$scene" --backend "${POLYDEM_BACKEND:-auto}" "$@"
