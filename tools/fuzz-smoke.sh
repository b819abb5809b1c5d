#!/usr/bin/env bash
# Fuzz smoke run for CI: each cargo-fuzz target of pbrt-import/fuzz (pbrt tokenizer+parser,
# PLY reader, motu package reader, AOV reader, OBJ import) for FUZZ_SECONDS (default 60) on stable Rust, starting
# from the committed corpus (read-only: new inputs go to a temporary directory).
#
#   tools/fuzz-smoke.sh                  # all targets, 60 s each
#   FUZZ_SECONDS=10 FUZZ_TARGETS=ply tools/fuzz-smoke.sh
#
# Stable only: RUSTC_BOOTSTRAP=1 lets cargo-fuzz pass its -Z flags; `--sanitizer none`
# keeps the sancov instrumentation libFuzzer needs without the ASan runtime.
# Cost from a cold cache on 2 cores: `cargo install cargo-fuzz` ~1.5 min, first build of
# the targets ~2 min, then FUZZ_SECONDS per target (about 8.5 min in all with defaults).
#
# Exit status: 0 when every target ran clean, or with a "SKIPPED: <why>" line when the fuzz
# toolchain cannot be installed; 1 on a finding (the input is printed and kept) or when the
# targets fail to build (an API change broke them: that is a real failure).
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
fuzz_dir=$root/pbrt-import/fuzz
seconds=${FUZZ_SECONDS:-60}
targets=${FUZZ_TARGETS:-"parse ply package aov obj"}
export RUSTC_BOOTSTRAP=1

if ! cargo fuzz --version >/dev/null 2>&1; then
    if [ "${FUZZ_NO_INSTALL:-0}" = 1 ]; then
        echo "SKIPPED: cargo-fuzz is not installed (FUZZ_NO_INSTALL=1)"
        exit 0
    fi
    echo "fuzz-smoke: installing cargo-fuzz" >&2
    if ! cargo install cargo-fuzz --locked >&2; then
        echo "SKIPPED: cargo-fuzz could not be installed (no registry access or no C++ toolchain?)"
        exit 0
    fi
fi

cd "$fuzz_dir"
echo "fuzz-smoke: building targets" >&2
cargo fuzz build --sanitizer none >&2

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
status=0
for target in $targets; do
    dict=()
    case $target in
        parse) dict=(-dict=pbrt.dict) ;;
        ply) dict=(-dict=ply.dict) ;;
    esac
    mkdir -p "$work/$target" "$work/artifacts-$target"
    echo "fuzz-smoke: $target for ${seconds}s" >&2
    if cargo fuzz run --sanitizer none "$target" "$work/$target" "corpus/$target" -- \
        "${dict[@]}" -max_total_time="$seconds" -max_len=65536 -timeout=10 \
        -rss_limit_mb=2048 -artifact_prefix="$work/artifacts-$target/" \
        -print_final_stats=1 >"$work/$target.log" 2>&1; then
        runs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$work/$target.log" | grep -o '[0-9]*$' || true)
        echo "fuzz-smoke: $target clean (${runs:-?} runs)"
    else
        status=1
        echo "FAILED: fuzz target $target found a problem:"
        grep -E 'panicked|ERROR|SUMMARY|alloc_guard' "$work/$target.log" | head -n 20 || true
        for f in "$work/artifacts-$target"/*; do
            [ -e "$f" ] || continue
            keep=$fuzz_dir/artifacts/$target
            mkdir -p "$keep"
            cp "$f" "$keep/"
            echo "input kept as $keep/$(basename "$f") (base64 below)"
            base64 -w 0 "$f" | head -c 4000
            echo
        done
    fi
done
exit $status
