#!/usr/bin/env bash
# The README's test command: installs what is missing, then runs every check CI runs.
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup.sh
export CARGO_TERM_COLOR=${CARGO_TERM_COLOR:-never}
# CI builds once from scratch: incremental state only costs disk (GBs) and time.
export CARGO_INCREMENTAL=${CARGO_INCREMENTAL:-0}
# GPU tests must run (lavapipe is installed above) with validation on: a missing device or any
# validation message fails them instead of skipping; so must the headless-browser test.
export MOTU_REQUIRE_GPU=1 MOTU_VALIDATION=1 MOTU_REQUIRE_BROWSER=1
echo "== cargo fmt --check"
cargo fmt --all -- --check
echo "== cargo clippy -D warnings"
cargo clippy --workspace --all-targets --locked -- -D warnings
echo "== fuzz smoke (parser, PLY reader, package reader; 30 s each)"
FUZZ_SECONDS=${FUZZ_SECONDS:-30} bash tools/fuzz-smoke.sh
echo "== cargo test (unit, integration, doc; benches run once each in test mode)"
# --no-fail-fast: one run names every failing test, not just the first binary's.
cargo test --workspace --all-targets --locked --no-fail-fast
cargo test --workspace --doc --locked
