#!/usr/bin/env bash
# Packs what a GPU machine without a Rust toolchain needs to run polydem and its tests: the
# release CLI in .device/bin, every release test binary in .device/tests (stripped), and
# .device/gpu-tests.sh, which runs them all with the GPU tests included. Copy the repository
# with .device/ to the GPU machine and run `bash .device/gpu-tests.sh` from its root; pass
# test-binary arguments after it (for example `--ignored` for the GPU variants only).
# Arguments to this script go to `cargo test --no-run` (for example `--test gpu_pipeline`).
set -euo pipefail
cd "$(git rev-parse --show-toplevel)"
# .device/ is local output: keep it out of git without touching .gitignore.
exclude=$(git rev-parse --git-path info/exclude)
mkdir -p "$(dirname "$exclude")"
grep -qx '/.device/' "$exclude" 2> /dev/null || echo '/.device/' >> "$exclude"
rm -rf .device
mkdir -p .device/bin .device/tests

# Copies the executables cargo reports (JSON on stdin): the CLI when $1 is "bin", the test
# binaries (named after their target, "-lib"/"-bin" for unit tests) when it is "test".
collect() {
  python3 -c '
import json, shutil, sys
want_test = sys.argv[1] == "test"
for line in sys.stdin:
    m = json.loads(line)
    exe = m.get("executable")
    if m.get("reason") != "compiler-artifact" or not exe or m["profile"]["test"] != want_test:
        continue
    if want_test:
        kind = m["target"]["kind"][0]
        name = m["target"]["name"] + ("" if kind == "test" else "-" + kind)
        shutil.copy(exe, ".device/tests/" + name)
    else:
        shutil.copy(exe, ".device/bin/")
' "$1"
}
cargo build --release --bins --message-format=json 2> /dev/null | collect bin
cargo test --release --no-run --message-format=json "$@" 2> /dev/null | collect test
strip --strip-debug .device/bin/* .device/tests/* 2> /dev/null || true

cat > .device/gpu-tests.sh << 'RUN'
#!/usr/bin/env bash
# Every packed test binary, GPU tests included, from the repository root.
cd "$(dirname "$0")/.."
export POLYDEM_ROOT=$PWD PATH=$PWD/.device/bin:$PATH
# Open MPI refuses root without these (the GPU machines run as root).
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
status=0
for t in .device/tests/*; do
  echo "=== $t"
  "$t" --include-ignored "$@" || status=1
done
exit $status
RUN
chmod +x .device/gpu-tests.sh
echo "packed .device/: $(du -sm .device | cut -f1) MiB"
