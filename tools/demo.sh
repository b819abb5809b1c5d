#!/usr/bin/env bash
# The README's demo command: installs what is missing, builds motu and runs `motu demo`.
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup.sh
cargo build --release --locked -p motu-cli
exec ./target/release/motu demo "$@"
