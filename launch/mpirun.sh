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
#
# Ctrl-C, `kill` (SIGTERM) or SIGHUP on this script stop every rank after the same step with
# the interrupt checkpoint written, however long that takes, and the script exits 130, 143 or
# 129; a second signal ends the job at once (docs/parallel.md, "Interrupting a run").
#
# On a GPU machine each rank drives the GPU of its node-local rank modulo the visible GPUs
# (docs/design.md §6); POLYDEM_BACKEND=cpu|cuda|auto (default auto) picks the backend.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if (($# < 2)); then
    sed -n '2,21p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'
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
if [[ "$(id -u)" == 0 ]]; then
    # Open MPI refuses root without these (containers, CI).
    export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
fi
# Open MPI 4 does not forward SIGINT or SIGTERM: interrupted, mpirun sends the ranks SIGCONT,
# waits odls_base_sigkill_timeout (1 s), sends SIGTERM, waits again and sends SIGKILL, reaping
# nothing and forwarding no output while it waits. That leaves a large run a second for its
# checkpoint, and a longer timeout holds every failed job for as long (a rank's non-zero exit
# takes the same path). SIGUSR1 mpirun forwards to every rank and then waits for them, and
# polydem stops on it as on SIGINT (src/interrupt.rs). So mpirun runs in a session of its own
# (a terminal's Ctrl-C reaches this script, not mpirun), with no terminal input (a job outside
# the terminal's foreground group would stop at its first read), and the first SIGINT, SIGTERM
# or SIGHUP here becomes SIGUSR1 for mpirun; a second is passed on as it is.
first=0
pass_on() { # the signal's number
    if ((first == 0)); then
        first=$1
        kill -USR1 "$job" 2> /dev/null || true
    else
        kill "-$1" "$job" 2> /dev/null || true
    fi
}
trap 'pass_on 2' INT
trap 'pass_on 15' TERM
trap 'pass_on 1' HUP
# shellcheck disable=SC2086
setsid "${MPIRUN:-mpirun}" "${launcher_args[@]}" ${MPIRUN_ARGS:-} \
    "$bin" "${POLYDEM_COMMAND:-run}" "$scene" --backend "${POLYDEM_BACKEND:-auto}" "$@" \
    < /dev/null &
job=$!
# `wait` returns early (> 128) when a trapped signal arrives; mpirun is then still running.
status=0
while :; do
    status=0
    wait "$job" || status=$?
    kill -0 "$job" 2> /dev/null || break
done
# The ranks end a stop on SIGUSR1 with status 0 (src/interrupt.rs); the script reports the
# signal it was sent, with the shell's 128 + signal.
if ((first != 0)); then
    exit $((128 + first))
fi
exit "$status"
