#!/usr/bin/env bash
# Installs what `make run` and `make test` need on Debian/Ubuntu, then returns quickly on every
# later call:
#
#   1. apt packages: libopenmpi-dev openmpi-bin libclang-dev pkg-config (rsmpi's build), plus
#      build-essential when there is no C compiler/linker and python3-venv when Python's venv
#      module is missing. Installed with apt-get as root, with `sudo -n` where that works;
#      otherwise the exact command is printed and the script stops.
#   2. cargo (Rust >= 1.85, for edition 2024): checked, never installed (rustup is the way).
#   3. .venv: a Python virtual environment with python/requirements.txt installed. A stamp file
#      holding the hash of requirements.txt (and the interpreter's version) skips pip when
#      nothing changed.
#
# Environment (for testing this script and for unusual machines):
#   POLYDEM_SETUP_UID=N     act as if `id -u` printed N (e.g. 1000 to exercise the non-root path)
#   POLYDEM_SETUP_NO_SUDO=1 act as if sudo were not available
#   POLYDEM_SETUP_DRY_RUN=1 print the install commands instead of running them
#   POLYDEM_SETUP_APT_PACKAGES="a b"  the apt packages to require (default: the list above)
#   PYTHON=python3.x        the interpreter that creates .venv (default: python3)
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv"
REQUIREMENTS="$ROOT/python/requirements.txt"
STAMP="$VENV/.polydem-requirements.stamp"
PYTHON="${PYTHON:-python3}"
DRY_RUN="${POLYDEM_SETUP_DRY_RUN:-0}"
MIN_RUST_MINOR=85 # edition 2024

say() { printf 'setup: %s\n' "$*"; }
die() {
    printf '\nsetup: ERROR: %s\n' "$1" >&2
    shift
    local line
    for line in "$@"; do printf '  %s\n' "$line" >&2; done
    printf '\n' >&2
    exit 1
}

# --- 1. System packages -------------------------------------------------------------------

read -r -a apt_packages <<<"${POLYDEM_SETUP_APT_PACKAGES:-libopenmpi-dev openmpi-bin libclang-dev pkg-config}"
if ! command -v cc >/dev/null 2>&1 || ! command -v c++ >/dev/null 2>&1; then
    # Rust links through the system C compiler; tests/cuda_geometry_host.rs compiles the CUDA
    # geometry headers as host C++.
    apt_packages+=(build-essential)
fi
if ! command -v "$PYTHON" >/dev/null 2>&1; then
    apt_packages+=(python3 python3-venv)
elif ! "$PYTHON" -c 'import venv, ensurepip' >/dev/null 2>&1; then
    apt_packages+=(python3-venv) # Debian splits venv/ensurepip out of python3
fi

missing=()
for pkg in "${apt_packages[@]}"; do
    # `dpkg -s` also succeeds for removed-but-not-purged packages; require "install ok installed".
    if ! dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q 'install ok installed'; then
        missing+=("$pkg")
    fi
done

if ((${#missing[@]} > 0)); then
    if ! command -v apt-get >/dev/null 2>&1; then
        die "missing system packages: ${missing[*]}" \
            "This script installs them on Debian/Ubuntu only (no apt-get here)." \
            "Install the equivalent packages with your system's package manager (Open MPI with" \
            "its development headers, libclang, pkg-config), then run make again."
    fi
    install_cmd="apt-get update && DEBIAN_FRONTEND=noninteractive apt-get install -y ${missing[*]}"
    uid="${POLYDEM_SETUP_UID:-$(id -u)}"
    if [[ "$uid" == 0 ]]; then
        runner=()
    elif [[ "${POLYDEM_SETUP_NO_SUDO:-0}" != 1 ]] && command -v sudo >/dev/null 2>&1 \
        && sudo -n true >/dev/null 2>&1; then
        runner=(sudo -n)
    else
        die "missing system packages: ${missing[*]}" \
            "You are not root and sudo is not available without a password. Install them with:" \
            "" \
            "    sudo sh -c 'apt-get update && DEBIAN_FRONTEND=noninteractive apt-get install -y ${missing[*]}'" \
            "" \
            "(or the same command as root), then run make again."
    fi
    say "installing missing system packages: ${missing[*]}"
    if [[ "$DRY_RUN" == 1 ]]; then
        say "[dry run] would run: ${runner[*]:+${runner[*]} }sh -c '$install_cmd'"
    else
        "${runner[@]}" sh -c "$install_cmd" || die "installing ${missing[*]} failed (see above)." \
            "The command was: ${runner[*]:+${runner[*]} }sh -c '$install_cmd'"
    fi
fi

# --- 2. Rust ------------------------------------------------------------------------------

if ! command -v cargo >/dev/null 2>&1; then
    if [[ -x "$HOME/.cargo/bin/cargo" ]]; then
        die "cargo is installed in $HOME/.cargo/bin but that folder is not on PATH." \
            "Run:  . \"\$HOME/.cargo/env\"   (or open a new shell), then run make again."
    fi
    die "cargo (Rust) is not installed. Install Rust with rustup:" \
        "" \
        "    curl --proto '=https' --tlsv1.2 -sSf https://sh.rustup.rs | sh -s -- -y" \
        "    . \"\$HOME/.cargo/env\"" \
        "" \
        "then run make again (see https://rustup.rs)."
fi
rust_minor="$(cargo --version | sed -n 's/^cargo 1\.\([0-9][0-9]*\)\..*/\1/p')"
if [[ -n "$rust_minor" ]] && ((rust_minor < MIN_RUST_MINOR)); then
    die "$(cargo --version) is too old: polydem uses Rust edition 2024 (Rust >= 1.$MIN_RUST_MINOR)." \
        "Update with:  rustup update stable"
fi

# --- 3. Python virtual environment --------------------------------------------------------

if [[ "$DRY_RUN" == 1 ]] && ! command -v "$PYTHON" >/dev/null 2>&1; then
    say "[dry run] $PYTHON is missing; stopping before the virtual environment"
    exit 0
fi
command -v "$PYTHON" >/dev/null 2>&1 || die "$PYTHON not found even after installing python3." \
    "Install Python 3 (python3 and python3-venv on Debian/Ubuntu) or set PYTHON=/path/to/python3."

key="$( (cat "$REQUIREMENTS" && "$PYTHON" -c 'import sys; print(sys.version)') | sha256sum | cut -d' ' -f1)"
if [[ -x "$VENV/bin/python" && -f "$STAMP" && "$(cat "$STAMP")" == "$key" ]] \
    && "$VENV/bin/python" -c 'pass' >/dev/null 2>&1; then
    say "system packages, cargo and .venv are up to date"
    exit 0
fi

if [[ "$DRY_RUN" == 1 ]]; then
    say "[dry run] would create $VENV and pip install -r $REQUIREMENTS"
    exit 0
fi

if ! [[ -x "$VENV/bin/python" ]] || ! "$VENV/bin/python" -m pip --version >/dev/null 2>&1; then
    say "creating the Python virtual environment $VENV"
    rm -rf "$VENV"
    if ! "$PYTHON" -m venv "$VENV"; then
        rm -rf "$VENV"
        die "'$PYTHON -m venv' failed. On Debian/Ubuntu install the venv module with:" \
            "" \
            "    sudo apt-get install -y python3-venv" \
            "" \
            "(for a non-default Python, python3.X-venv), then run make again."
    fi
fi

say "installing Python packages from python/requirements.txt into .venv"
rm -f "$STAMP"
"$VENV/bin/python" -m pip install --disable-pip-version-check -q -r "$REQUIREMENTS" \
    || die "pip install -r python/requirements.txt failed (see above)." \
        "PyPI must be reachable; retry, or install by hand: $VENV/bin/python -m pip install -r $REQUIREMENTS"
"$VENV/bin/python" -c 'import numpy, scipy, manifold3d, shapely, meshio' \
    || die "the Python packages were installed but do not import (see above)."
printf '%s\n' "$key" >"$STAMP"
say ".venv ready ($("$VENV/bin/python" --version))"
