#!/usr/bin/env bash
# Fuzzes icrender with cargo-fuzz (libFuzzer) on the stable toolchain; see docs/FUZZING.md.
#
#   scripts/fuzz.sh [SECONDS] [TARGET...]
#
# SECONDS per target (default 60); TARGETs among scene_load, cache_file, records (default: all).
# JOBS=2 runs two targets at a time. Seeds are (re)made into fuzz/corpus/TARGET, which keeps
# what earlier runs found; crashes land in fuzz/artifacts/TARGET, logs in fuzz/logs/TARGET.log.
# Needs: cargo-fuzz (cargo install cargo-fuzz), clang++ and python3.
set -euo pipefail
cd "$(dirname "$0")/.."

seconds=${1:-60}
shift || true
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(scene_load cache_file records)
jobs=${JOBS:-1}

# cargo-fuzz needs nightly-only rustc flags (-Zsanitizer); the stable compiler accepts them
# with RUSTC_BOOTSTRAP=1. The C++ layer is compiled with ASan, UBSan (trap mode) and libFuzzer
# coverage by the wrapper; the Rust side gets ASan and coverage from cargo-fuzz itself.
export RUSTC_BOOTSTRAP=1
export CXX="$PWD/fuzz/cxx-sanitize.sh"
# LeakSanitizer is off: a leak is not what these targets look for, and the libraries the loader
# links (OpenImageIO, Embree) keep one-time allocations that it would report.
export ASAN_OPTIONS="${ASAN_OPTIONS:-detect_leaks=0:allocator_may_return_null=0}"

# Seeds: the project's scenes, hand-made records, and the hostile corpus of tests/hostile.rs.
hostile=$(mktemp -d)
trap 'rm -rf "$hostile"' EXIT
HOSTILE_CORPUS_DIR="$hostile" cargo test --release -q --test hostile -- --ignored --exact write_corpus \
    >/dev/null 2>&1 || echo "fuzz.sh: could not write the hostile corpus; seeding without it" >&2
python3 fuzz/make_seeds.py fuzz/corpus "$hostile/scenes" >/dev/null
# A scene the loader accepts may not take more than this (it refuses it with a clear error);
# it keeps accepted inputs below libFuzzer's -rss_limit_mb.
export ICRENDER_MAX_SCENE_MEMORY_MB=${ICRENDER_MAX_SCENE_MEMORY_MB:-1024}
for t in "${targets[@]}"; do cargo fuzz build --fuzz-dir fuzz "$t"; done
mkdir -p fuzz/logs

run_one() {
    local t=$1
    # -rss_limit_mb: a scene the loader accepts may legitimately need some memory (the C++
    # arrays and their Rust copies); anything above this is a finding. -timeout: a single input
    # taking longer is a hang.
    local rc=0
    cargo fuzz run --fuzz-dir fuzz "$t" "fuzz/corpus/$t" -- \
        -max_total_time="$seconds" -max_len=65536 -rss_limit_mb=4096 -timeout=20 -print_final_stats=1 \
        >"fuzz/logs/$t.log" 2>&1 || rc=$?
    local last
    last=$(grep -E '^#[0-9]+' "fuzz/logs/$t.log" | tail -1 || true)
    echo "$t: exit $rc; $last"
    ls "fuzz/artifacts/$t" 2>/dev/null | sed 's/^/    artifact: /' || true
    return 0
}

running=0
for t in "${targets[@]}"; do
    run_one "$t" &
    running=$((running + 1))
    if [ "$running" -ge "$jobs" ]; then
        wait -n || true
        running=$((running - 1))
    fi
done
wait
