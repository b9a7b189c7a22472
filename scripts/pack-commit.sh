#!/usr/bin/env bash
# Adds the release CLI of another commit to .device/bin as polydem_<name>, for a GPU A/B in the
# same call as this commit's CLI (`scripts/gpu_session.sh regress`). Run after scripts/gpu-pack.sh:
#   bash scripts/pack-commit.sh bb55eb6 before_depth
# Builds in a temporary worktree into target/commits: a target directory of its own, since
# cargo names a package's outputs without its path, and a build of another checkout into
# target/ would replace this commit's CLI there with one cargo then takes for up to date. The
# first build compiles every dependency (minutes); later ones only polydem.
set -euo pipefail
cd "$(git rev-parse --show-toplevel)"
[ $# -eq 2 ] || { echo "usage: $0 COMMIT NAME" >&2; exit 2; }
commit=$1 name=$2
[ -d .device/bin ] || { echo "no .device/bin: run scripts/gpu-pack.sh first" >&2; exit 2; }
tree=$(mktemp -d)
trap 'git worktree remove --force "$tree" > /dev/null 2>&1 || true' EXIT
git worktree add --detach "$tree" "$commit" > /dev/null
CARGO_TARGET_DIR="$PWD/target/commits" cargo build --release --bin polydem \
  --manifest-path "$tree/Cargo.toml" 2> /dev/null
cp target/commits/release/polydem ".device/bin/polydem_$name"
strip --strip-all ".device/bin/polydem_$name" 2> /dev/null || true
echo "packed .device/bin/polydem_$name ($(git rev-parse --short "$commit")); .device/: $(du -sm .device | cut -f1) MiB"
