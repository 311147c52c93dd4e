# palpate: one-command set-up on a fresh machine (needs python3 with venv, and cargo).
#   make demo   set up .venv, build the extension (release), run the demo
#   make test   set up, then cargo test --release, the release wheel, pytest, make lint and make fuzz-ci
#   make wheel  the release wheel in dist/: abi3 (CPython >= 3.9), manylinux_2_28, stripped
#   make lint   cargo fmt --check, clippy -D warnings, cargo doc -D warnings, stubtest, the fuzz targets compiled (all in make test)
#   make browser  Debian's chromium for the viewer's browser test (as root with apt-get; in make test)
# The set-up is stamp-file driven: a warm re-run is a no-op, an edit to any .rs / Cargo.toml /
# pyproject.toml rebuilds the extension. Python sources are installed editable (maturin develop),
# so edits to python/palpate/*.py need no rebuild.

SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
# Versions that build together on this machine (see shared/design/stack-notes.md).
PY_DEPS := maturin==1.16.0 numpy==2.4.6 meshio==5.3.5 matplotlib==3.11.2 pytest==9.2.0 \
           scipy==1.17.1 scikit-fem==12.0.2 \
           viser==1.1.1 playwright==1.65.2 gmsh==4.15.2
# scipy, scikit-fem: the independent reference in python/tests; gmsh: the tet mesher of Rodero's
# reference wall (palpate validate, the validate extra; a 40 MB wheel); viser, playwright: `palpate view`
# and its browser test (the view extra). viser from its PyPI wheel (a source install builds its
# client with node from the network). Playwright drives the system's Chromium (`make browser`):
# never `playwright install`.
# Batch studies (palpate sweep / fit; the `study` extra), pinned to versions that install together.
STUDY_DEPS := dask==2026.8.0 distributed==2026.8.0 pyarrow==26.0.1
# `make wheel` only: zig as the linker, against glibc 2.28's symbols, so that the wheel installs on
# common Linux systems (a plain build here needs glibc 2.34: manylinux_2_34).
WHEEL_DEPS := ziglang==0.17.1
# `make lint` / `make stubtest`: mypy's stubtest checks python/palpate/_palpate.pyi against the
# extension it describes.
LINT_DEPS := mypy==2.4.1
DIST := dist

RUST_INPUTS := $(shell find crates python/src -name '*.rs' 2>/dev/null) \
               $(wildcard crates/*/Cargo.toml) Cargo.toml $(wildcard Cargo.lock) python/Cargo.toml python/pyproject.toml

export MPLBACKEND ?= Agg

.PHONY: all setup demo test cargo-test pytest wheel lint fmt clippy rustdoc stubtest fuzz-check clean distclean browser

all: setup

setup: $(VENV)/.built
# The Rodero et al. left ventricle (python -m palpate.data): fetched once, after the extension is
# built (palpate must import); offline, set-up goes on and the tests that need it skip.
setup: $(VENV)/.data

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)

$(VENV)/.deps: $(BIN)/python Makefile
	$(BIN)/python -m pip install -q --disable-pip-version-check --upgrade pip
	$(BIN)/python -m pip install -q --disable-pip-version-check $(PY_DEPS) $(STUDY_DEPS)
	touch $@

$(VENV)/.built: $(VENV)/.deps $(RUST_INPUTS)
	cd python && VIRTUAL_ENV=$(CURDIR)/$(VENV) ../$(BIN)/maturin develop --release -q
	touch $@

$(VENV)/.data: python/palpate/data.py | $(VENV)/.built
	@if $(BIN)/python -m palpate.data; then touch $@; \
	else echo "palpate: could not fetch the Rodero LV data set (see above); tests that need it will skip" >&2; fi

demo: setup
	$(BIN)/python -m palpate.demo

$(VENV)/.wheel-deps: $(VENV)/.deps
	$(BIN)/python -m pip install -q --disable-pip-version-check $(WHEEL_DEPS)
	touch $@

# Cargo profile `wheel` (Cargo.toml): release without debug info, stripped, in its own target
# folder, so the release builds of `make test` keep their debug info. python/tests/test_wheel.py
# installs the newest dist/ wheel into a clean venv and runs the demo from outside the tree.
wheel: $(VENV)/.wheel-deps
	rm -f $(DIST)/palpate-*.whl
	cd python && PATH=$(abspath $(BIN)):$$PATH $(abspath $(BIN))/maturin build -q --profile wheel --zig \
	    --compatibility manylinux_2_28 -o $(abspath $(DIST))

test: cargo-test pytest lint fuzz-ci

cargo-test:
	cargo test --release -q

# The session's temporary files in the clone (.pytest-tmp, emptied at each start), not under the
# machine's shared /tmp/pytest-of-<user>, whose numbered folders another session on the same
# machine may clean away mid-run (a CI run of 2026-11-26 saw every tmp_path fixture fail from
# its 231st test on, which a fresh clone here never reproduced).
pytest: setup wheel browser
	$(BIN)/python -m pytest -q --basetemp=$(CURDIR)/.pytest-tmp python/tests

# The browser test's Chromium (python/tests/test_view.py): Debian's package, installed where the
# set-up runs as root with apt-get (~90 s, once); elsewhere the browser tests skip, saying why.
browser:
	@if command -v chromium >/dev/null 2>&1 || [ -n "$$PALPATE_CHROMIUM" ]; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	  echo "palpate: installing Debian's chromium for the browser tests (apt-get, ~90 s)" >&2; \
	  (apt-get update -q && DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium) >/dev/null \
	    || echo "palpate: apt-get install chromium failed: the browser tests will skip" >&2; \
	else echo "palpate: no chromium and no root apt-get: the browser tests will skip (apt-get install -y chromium)" >&2; fi

$(VENV)/.lint-deps: $(VENV)/.deps
	$(BIN)/python -m pip install -q --disable-pip-version-check $(LINT_DEPS)
	touch $@

lint: fmt clippy rustdoc stubtest fuzz-check

# The Rust sources in the house style (rustfmt.toml).
fmt:
	cargo fmt --all -- --check

clippy:
	cargo clippy --workspace --all-targets -- -D warnings

rustdoc:
	RUSTDOCFLAGS="-D warnings" cargo doc --no-deps --workspace

# The fuzz targets (fuzz/: their own workspace, built by cargo-fuzz on nightly) compiled on stable,
# so that a change of the core's API cannot break them unnoticed between `make fuzz` runs.
# CUSTOM_LIBFUZZER_PATH points libfuzzer-sys's build script at a library instead of compiling
# libFuzzer's C++ (a check never links it, so the path need not exist). ~20 s cold (palpate-core
# checked once more, in fuzz/target), under a second warm.
fuzz-check:
	CUSTOM_LIBFUZZER_PATH=$(CURDIR)/fuzz/target/none/libfuzzer.a cargo check --locked --manifest-path fuzz/Cargo.toml --bins

# Names only the stub has (the TypedDicts of returned dicts) are listed in the allowlist.
stubtest: setup $(VENV)/.lint-deps
	$(BIN)/python -m mypy.stubtest palpate._palpate --allowlist python/stubtest-allowlist.txt

clean:
	rm -f $(VENV)/.built python/palpate/*.so
	rm -rf out $(DIST) .pytest-tmp

distclean: clean
	rm -rf $(VENV) target

# Hardening (issue 15). The malformed-input corpus (python/tests/test_corpus.py) and the readers'
# mutation fuzzing (test_corpus_fuzz.py) run in `make pytest`. Coverage-guided fuzzing of the
# model-file loader and the mesh validators (fuzz/, libFuzzer) needs a nightly toolchain and
# cargo-fuzz (`cargo install cargo-fuzz`): `make fuzz` runs every target FUZZ_SECONDS each (CI:
# `make fuzz-ci`, part of `make test`, 20 s each; see below).
# FUZZ_SEED: libFuzzer's random seed; 0 (the default) draws a new one each run (exploration).
# fuzz-ci fixes it, so that CI's verdict on a commit is reproducible: a crash found by exploring is
# fixed and its input kept in fuzz/seeds/TARGET/, which every run replays first.
FUZZ_SECONDS ?= 60
FUZZ_SEED ?= 0
FUZZ_TARGETS := model_file model_payload tet_mesh tri_surface bridge_packet recording
.PHONY: fuzz fuzz-ci
fuzz:
	cd fuzz && for t in $(FUZZ_TARGETS); do \
	  mkdir -p corpus/$$t && cargo +nightly fuzz run $$t corpus/$$t seeds/$$t -- -max_total_time=$(FUZZ_SECONDS) \
	    -seed=$(FUZZ_SEED) -rss_limit_mb=2048 -timeout=10 || exit 1; done
# fuzz-ci (part of `make test`): where a nightly toolchain is installed, cargo-fuzz is installed
# from crates.io if missing (pinned; ~25 s) and every target runs 20 s (~2.5 min cold in all); a
# crash fails the run. Without nightly (or if cargo-fuzz cannot be installed) it is skipped with a
# note: the corpus and the Python readers' mutation fuzzing still run in pytest.
CARGO_FUZZ_VERSION := 0.13.1
fuzz-ci:
	@if ! rustup run nightly rustc --version >/dev/null 2>&1; then \
	  echo "fuzz-ci: no nightly toolchain (rustup toolchain install nightly): skipped"; exit 0; fi; \
	if ! cargo +nightly fuzz --version >/dev/null 2>&1; then \
	  cargo install cargo-fuzz --version $(CARGO_FUZZ_VERSION) --locked -q || \
	  { echo "fuzz-ci: cargo-fuzz could not be installed: skipped"; exit 0; }; fi; \
	$(MAKE) fuzz FUZZ_SECONDS=20 FUZZ_SEED=1
