# polydem: `make run` (the main job) and `make test` (the test suite) work on a fresh
# Debian/Ubuntu machine: both first run scripts/setup.sh, which installs what is missing (apt
# packages for Open MPI and bindgen, the Python virtual environment .venv) and checks for cargo.
#
#   make run       build the release CLI and run the quickstart scene (launch/quickstart/)
#   make probe     the contact-geometry probe on the examples in launch/probe/
#   make test      cargo test --release, with the oracles' Python in POLYDEM_PYTHON and
#                  PyPI's NVRTC on LD_LIBRARY_PATH (kernel compile check)
#   make validate  the full-size validation cases that `make test` runs as smaller twins
#                  (tests marked `#[ignore = "full validation: make validate"]`)
#   make faults    the bad-input, fault and interrupt tests of docs/validation.md §11 alone
#                  (they run in `make test` too): real mpirun on 2-3 ranks, signals, kills
#   make lint      cargo fmt --check, clippy -D warnings on every target, rustdoc -D warnings,
#                  no import cycle between top-level modules, and docs/design.md's module
#                  graph block current (scripts/module_graph.py; `make graph` rewrites it)
#   make graph     print the module import graph and the largest source files, and write them
#                  into docs/design.md (Architecture at a glance)
#   make setup     only the installation step
#   make clean-venv   remove .venv (the next setup recreates it)
#
# What they cost on a 2-core machine (cold: a fresh clone after setup, the build included;
# warm: built before):
#
#   make run       cold 8-10 min (the build) + the scene; warm the scene alone
#   make test      cold about 20 min, warm about 11 (NVRTC 3, the small pour 3, the rest 5)
#   make validate  cold about 20 min, warm about 16 (the full pour; the ensemble of cube boxes)
#   make lint      cold about 6 min (clippy checks every target, rustdoc builds the
#                  dependencies in the dev profile), warm under 1 min
#   make probe     cold 8-10 min (the build), warm seconds
#   make faults    warm about 1 min
#
# `make lint` is not part of `make test`: formatting or lint findings are review findings, not
# failed tests, so they should not stop a user's `make test` from reporting what the tests
# say. CI (.ci/run) runs `make test`, `make validate`, then `make lint`. Run `make lint` and
# `make test` before committing (CONTRIBUTING.md).

SHELL := /bin/bash
.SHELLFLAGS := -eu -o pipefail -c
.DEFAULT_GOAL := help

ROOT := $(abspath $(dir $(lastword $(MAKEFILE_LIST))))
# rustup installs into ~/.cargo/bin; a shell opened before the install may not have it yet.
export PATH := $(HOME)/.cargo/bin:$(PATH)

CARGO ?= cargo
TARGET_DIR := $(or $(CARGO_TARGET_DIR),$(ROOT)/target)
POLYDEM := $(TARGET_DIR)/release/polydem
VENV_PYTHON := $(ROOT)/.venv/bin/python
PROBE_OUT := $(ROOT)/out/probe

.PHONY: help setup build run probe test validate faults lint graph clean-venv

help:
	@sed -n '1,/^$$/p' $(ROOT)/Makefile | sed 's/^# \{0,1\}//'

setup:
	@bash $(ROOT)/scripts/setup.sh

# Built together with one integration test so that dependencies get the same features as under
# `cargo test` (dev-dependencies unify features): `make run` and `make test` then share every
# compiled artifact instead of building the dependency graph twice (minutes on 2 cores).
build: setup
	cd $(ROOT) && $(CARGO) build --release --bin polydem --test probe_manifold

# The main job: the quickstart scene (about 2000 dodecahedra poured into a hopper), on the GPU
# when one is present and the CUDA backend is built, else on the CPU; ParaView output and
# summary.json go to out/quickstart/, and the summary is printed.
run: build
	@cd $(ROOT) && $(POLYDEM) run launch/quickstart/quickstart.toml --backend auto --overwrite

# The contact-geometry probe on the example pairs and wall cases of launch/probe/ (see
# launch/probe/README.md).
probe: build
	@mkdir -p $(PROBE_OUT)
	@cd $(ROOT) && for q in overlap:pairs wall:wall; do \
	    query=$${q%%:*}; input=launch/probe/$${q#*:}.json; \
	    echo; echo "== polydem probe $$query $$input"; \
	    $(POLYDEM) probe $$query $$input | tee $(PROBE_OUT)/$$query.jsonl; \
	    echo "-- summary"; \
	    $(VENV_PYTHON) scripts/probe_report.py $$query $$input $(PROBE_OUT)/$$query.jsonl; \
	done
	@echo; echo "Results also in out/probe/*.jsonl; what they mean: launch/probe/README.md"

# NVRTC from PyPI (python/requirements.txt), for the kernel compile check without a GPU; a
# system CUDA install found first on the library path takes precedence.
NVRTC_LIB = $(firstword $(wildcard $(ROOT)/.venv/lib/python3*/site-packages/nvidia/cu13/lib))

test: setup
	cd $(ROOT) && LD_LIBRARY_PATH=$${LD_LIBRARY_PATH:+$$LD_LIBRARY_PATH:}$(NVRTC_LIB) \
	    POLYDEM_PYTHON=$(VENV_PYTHON) $(CARGO) test --release

# The full-size validation cases: each `BINARY:TEST` is a test marked
# `#[ignore = "full validation: make validate"]` whose smaller twin runs in `make test`. Named
# one by one, so that `--ignored` does not also pick the GPU tests.
VALIDATE_TESTS := validation_pour:poured_dodecahedra_settle_to_the_experimental_packing_fraction \
    validation_contact:aligned_cubes_converge_over_an_ensemble_of_boxes

validate: setup
	cd $(ROOT) && for t in $(VALIDATE_TESTS); do \
	    POLYDEM_PYTHON=$(VENV_PYTHON) $(CARGO) test --release --test $${t%%:*} -- \
	        --ignored --exact $${t#*:}; \
	done

# The tests of docs/validation.md §11 (bad input, faults and interrupts): `BINARY` runs every
# test of that file, `BINARY:a,b` those whose names contain a or b.
FAULT_TESTS := scene_limits shape_templates probe_cli io_output restart_integrity run_restart \
    mpi_signals scene_files:no_shipped_scene_warns,missing_files \
    mpi_decomposition:interrupting,stops_every_rank,refused stability

faults: setup
	cd $(ROOT) && for t in $(FAULT_TESTS); do \
	    filters=$$([[ $$t == *:* ]] && echo "$${t#*:}" | tr ',' ' ' || true); \
	    POLYDEM_PYTHON=$(VENV_PYTHON) $(CARGO) test --release --test $${t%%:*} -- $$filters; \
	done

lint: setup
	cd $(ROOT) && $(CARGO) fmt --check
	cd $(ROOT) && $(CARGO) clippy --release --all-targets -- -D warnings
	cd $(ROOT) && RUSTDOCFLAGS=-Dwarnings $(CARGO) doc --no-deps
	cd $(ROOT) && python3 scripts/module_graph.py --check
	cd $(ROOT) && python3 scripts/module_graph.py --check-doc docs/design.md

graph:
	@cd $(ROOT) && python3 scripts/module_graph.py && python3 scripts/module_graph.py --update docs/design.md

clean-venv:
	rm -rf $(ROOT)/.venv
