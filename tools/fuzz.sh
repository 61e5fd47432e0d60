#!/usr/bin/env bash
# Fuzzes cdvol with the proptest targets of tests/fuzz.rs: the packed-file
# reader (mutated files opened, inspected, rendered, exported), the
# traversal (random grids and rays from arbitrary f64 bit patterns) and
# the input readers (fuzz_readers_*: mutated NRRD, NIfTI, raw stack
# sidecar and DICOM inputs opened and read slice by slice).
#
#   tools/fuzz.sh [SECONDS]       # default 300
#
# Builds the fuzz test in release mode with overflow checks and debug
# assertions on (as `cargo test` has them, so an arithmetic overflow is a
# failure, not a silent wrap), in its own target directory (target/fuzz, so
# the normal release build is left alone), then runs it again and again
# with a fresh random PROPTEST_RNG_SEED and CDVOL_FUZZ_CASES cases per test
# (default 1000) until SECONDS of running have passed (the build is not
# counted). Stops at the first failing run. Prints the cases run and
# whether a failure was persisted to tests/fuzz.proptest-regressions, which
# the normal `cargo test --test fuzz` replays first from then on.
#
# Environment: CDVOL_FUZZ_CASES (cases per test per run),
# CDVOL_FUZZ_TARGET_DIR (default target/fuzz).
set -u -o pipefail

cd "$(dirname "$0")/.."
budget=${1:-300}
case "$budget" in
'' | *[!0-9]*)
    echo "usage: tools/fuzz.sh [SECONDS]" >&2
    exit 2
    ;;
esac
per_run=${CDVOL_FUZZ_CASES:-1000}
export CARGO_TARGET_DIR=${CDVOL_FUZZ_TARGET_DIR:-target/fuzz}
export CARGO_PROFILE_RELEASE_OVERFLOW_CHECKS=true
export CARGO_PROFILE_RELEASE_DEBUG_ASSERTIONS=true
reg=tests/fuzz.proptest-regressions
sum_of() { if [ -f "$1" ]; then cksum <"$1"; else echo none; fi; }
before=$(sum_of "$reg")

echo "fuzz: building tests/fuzz.rs (release, overflow checks on) in $CARGO_TARGET_DIR ..."
build_log=$(mktemp)
if ! cargo test --release --test fuzz --no-run >"$build_log" 2>&1; then
    cat "$build_log" >&2
    echo "fuzz: build failed" >&2
    exit 2
fi
bin=$(sed -n 's/.*Executable tests\/fuzz.rs (\(.*\))$/\1/p' "$build_log" | tail -n 1)
rm -f "$build_log"
if [ ! -x "$bin" ]; then
    echo "fuzz: cannot find the test executable" >&2
    exit 2
fi

logs="$CARGO_TARGET_DIR/fuzz-logs"
mkdir -p "$logs"
start=$(date +%s)
deadline=$((start + budget))
runs=0
reader=0
traversal=0
inputs=0
failed=""
refused=0
num() { sed -n "s/.*$1.*/\\1/p" "$2" | head -n 1; }
echo "fuzz: $per_run cases per test per run, for ${budget} s"
while [ "$(date +%s)" -lt "$deadline" ]; do
    seed=$(od -An -N8 -tu8 /dev/urandom | tr -d ' ')
    log="$logs/run-$seed.log"
    # A run that outlives the budget by 10 minutes is a hang.
    left=$((deadline - $(date +%s) + 600))
    CDVOL_FUZZ_CASES=$per_run PROPTEST_RNG_SEED=$seed \
        timeout "$left" "$bin" --nocapture --test-threads=2 fuzz_ >"$log" 2>&1
    rc=$?
    runs=$((runs + 1))
    r=$(sed -n 's/^cdvol-fuzz: fuzz::fuzz_packed_reader: \([0-9]*\) cases$/\1/p' "$log" | head -n 1)
    t=$(sed -n 's/^cdvol-fuzz: fuzz::fuzz_traversal: \([0-9]*\) cases$/\1/p' "$log" | head -n 1)
    reader=$((reader + ${r:-0}))
    traversal=$((traversal + ${t:-0}))
    for i in $(sed -n 's/^cdvol-fuzz: fuzz::fuzz_readers_[a-z]*: \([0-9]*\) cases$/\1/p' "$log"); do
        inputs=$((inputs + i))
    done
    a=$(num 'fuzz_traversal: \([0-9]*\) grids refused' "$log")
    refused=$((refused + ${a:-0}))
    if [ $rc -ne 0 ]; then
        case $rc in
        124) failed="run with PROPTEST_RNG_SEED=$seed hung (timeout)" ;;
        101) failed="run with PROPTEST_RNG_SEED=$seed failed" ;;
        *) failed="run with PROPTEST_RNG_SEED=$seed crashed (exit $rc; the input of an aborted case is left in $CARGO_TARGET_DIR/tmp/cdvol-fuzz-*/: case.cdv of the packed reader, the files of an input reader)" ;;
        esac
        echo "fuzz: $failed; log: $log"
        grep -E "^(Test failed|minimal failing input|thread .* panicked)" "$log" | head -n 5
        break
    fi
    rm -f "$log"
done
elapsed=$(($(date +%s) - start))
after=$(sum_of "$reg")

echo "fuzz: $runs runs in ${elapsed} s: $reader packed-reader cases, $traversal traversal cases, $inputs input-reader cases ($((reader + traversal + inputs)) in all)"
echo "fuzz: $refused traversal cases had grids beyond MAX_COORD_MM (refused, as prep refuses them)"
if [ "$before" != "$after" ]; then
    echo "fuzz: a failure was persisted to $reg (cargo test --test fuzz replays it)"
else
    echo "fuzz: no failure persisted ($reg unchanged)"
fi
if [ -n "$failed" ]; then
    exit 1
fi
