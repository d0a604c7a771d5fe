# The two quick-start commands:  `make run` (the main job) and `make test` (every test).
# Both install what they need into .venv first (scripts/setup.sh).
VENV ?= .venv
BIN := $(VENV)/bin

.PHONY: run test bench lint setup wheel docs safety-gym

setup:
	@bash scripts/setup.sh

## The main job on its defaults: train the four configurations (2 seeds each, a budget of
## about 6 minutes from nothing on 2 cores, setup included), evaluate them, and write figures
## and a results table.
run: setup
	$(BIN)/python -m tlshield reproduce --out results

## Every test: Rust (cargo test), Python (pytest on every core, pytest-xdist; the benchmark
## scripts and the examples run on tiny budgets, so their comparison tools and third-party
## environments are installed too, Safety-Gymnasium included), the docs' strict build, and the wheel installed and run in
## fresh venvs without Rust.
test:
	@EXTRAS=train,test,bench,examples,build,docs bash scripts/setup.sh
	@bash scripts/setup-safety-gym.sh
	cargo test --workspace
	$(BIN)/python -m pytest -n auto --durations=10
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --quiet
	bash scripts/check-wheel.sh

## Safety-Gymnasium (safety-gymnasium 1.0.0, mujoco 2.3.7) for tlshield/SafetyPointGoal*-v0 and
## `tlshield benchmark safety-gym` (docs/guides/safety-gym.md).
safety-gym:
	@EXTRAS=train bash scripts/setup.sh
	@bash scripts/setup-safety-gym.sh

## A manylinux wheel and an sdist in dist/ (maturin with zig; auditwheel names the tag).
wheel:
	@EXTRAS=build bash scripts/setup.sh
	CARGO_TARGET_DIR=target/wheel PATH="$(CURDIR)/$(BIN):$$PATH" $(BIN)/maturin build --release --zig --compatibility manylinux2014 --out dist
	$(BIN)/maturin sdist --out dist
	$(BIN)/auditwheel show dist/tlshield-*manylinux*.whl

## The documentation site, built and served at http://127.0.0.1:8000.
docs:
	@EXTRAS=docs bash scripts/setup.sh
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs serve

## Benchmarks: criterion, then the Python comparisons (rtamt, argus; ltlf2dfa + mona; cvxpy,
## clarabel; cbfpy; qpth and cvxpylayers).
bench:
	@EXTRAS=train,test,bench bash scripts/setup.sh
	cargo bench -p tlshield-bench
	$(BIN)/python benches/compare_robustness.py
	$(BIN)/python benches/compare_automaton.py --install-mona
	$(BIN)/python benches/compare_shield.py
	$(BIN)/python benches/compare_routing.py
	$(BIN)/python benches/compare_cbfpy.py
	$(BIN)/python benches/compare_grad.py

## Formatting and lints (rustfmt, clippy, rustdoc, ruff, stubtest).
lint:
	@EXTRAS=train,test,lint bash scripts/setup.sh
	cargo fmt --all -- --check
	cargo clippy --workspace --all-targets -- -D warnings
	RUSTDOCFLAGS="-D warnings" cargo doc --no-deps --workspace
	$(BIN)/ruff check python tests benches examples
	$(BIN)/ruff format --check python tests benches examples
	$(BIN)/python -m mypy.stubtest tlshield._core --allowlist stubtest_allow.txt
