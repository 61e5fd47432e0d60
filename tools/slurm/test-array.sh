#!/usr/bin/env bash
# End-to-end test of the Slurm scripts on a real (local, one-node) Slurm:
# builds cdvol (release) if needed, makes a small sphere phantom and preps
# it, starts tools/slurm/local-cluster.sh (and stops it at the end only if
# it started it), submits a 4-shard render array plus the assemble step with
# submit.sh, waits for both, and checks that the assembled PNG is
# byte-identical (cmp) to a single-process `cdvol render` with the same
# options. Also renders a 6-frame turntable in 3 shards (split by frame) and
# compares every frame with a single-process turntable, and preps a CT
# phantom in 4 shards with submit-prep.sh (pass 1 array, pass 2 array,
# merge) and compares the packed file with a single-process prep. Prints the job ids,
# each task's node, state and run time, and PASS or FAIL; exits non-zero on
# failure.
#
# usage: tools/slurm/test-array.sh        (as root; see local-cluster.sh)
#
# Environment:
#   CDVOL     binary to test [target/release/cdvol, built if missing or older
#             than src/]
#   SHARDS    number of shards [4]
#   TIMEOUT   seconds to wait for the jobs [300]
#   KEEP=1    keep the work directory (it is kept anyway on failure)
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
root=$(cd "$here/../.." && pwd)
shards=${SHARDS:-4}
timeout=${TIMEOUT:-300}
render_args=(--width 512 --height 512 --view "30,20" --mode surface -q)
tt_frames=6
tt_shards=3
tt_args=(--width 128 --height 128 --view "30,20" --mode surface --frames "$tt_frames" --orbit 90 -q)

say() { echo "test-array: $*"; }
fail() {
    echo "test-array: FAIL: $*" >&2
    keep=1
    exit 1
}

# --- cdvol ---------------------------------------------------------------
if [ -n "${CDVOL:-}" ]; then
    [ -x "$CDVOL" ] || fail "CDVOL=$CDVOL is not executable"
else
    CDVOL=$root/target/release/cdvol
    if [ ! -x "$CDVOL" ] ||
        [ -n "$(find "$root/src" "$root/Cargo.toml" "$root/Cargo.lock" -newer "$CDVOL" -print -quit)" ]; then
        say "building cdvol (cargo build --release)"
        (cd "$root" && cargo build --release --quiet) || fail "cargo build --release failed"
    fi
fi
CDVOL=$(realpath "$CDVOL")
export CDVOL
say "cdvol: $CDVOL ($("$CDVOL" --version))"

# --- volume ----------------------------------------------------------------
work=$(mktemp -d "${TMPDIR:-/tmp}/cdvol-slurm-test.XXXXXX")
chmod 755 "$work"
keep=${KEEP:-0}
started=0
cleanup() {
    local rc=$?
    if [ $started = 1 ]; then
        "$here/local-cluster.sh" stop || true
    fi
    if [ "$keep" = 1 ]; then
        echo "test-array: work directory kept: $work"
    else
        rm -rf "$work"
    fi
    echo "test-array: total ${SECONDS}s"
    exit $rc
}
trap cleanup EXIT

msg=$("$CDVOL" phantom spheres -q -o "$work/s.json" --size 96 --per-axis 3) || fail "cdvol phantom failed"
iso=$(sed -n 's/.*iso \([-+0-9.eE]*\).*/\1/p' <<< "$msg")
[ -n "$iso" ] || fail "no iso value in: $msg"
"$CDVOL" prep -q "$work/s.json" -o "$work/s.cdv" --iso "$iso" > /dev/null || fail "cdvol prep failed"
rm -f "$work/s.raw"
say "volume: $work/s.cdv (96^3 spheres, iso $iso)"
prep_args=(--iso 300 --brick 8)
"$CDVOL" phantom ct -q --dims 64,60,90 --dtype u16 -o "$work/ct.json" > /dev/null || fail "cdvol phantom ct failed"
"$CDVOL" prep -q "$work/ct.json" -o "$work/ct-single.cdv" "${prep_args[@]}" > /dev/null ||
    fail "single-process prep failed"
say "prep input: $work/ct.json (64 x 60 x 90 u16 CT phantom), single prep ${prep_args[*]}"

# --- cluster -----------------------------------------------------------------
eval "$("$here/local-cluster.sh" env)"
if "$here/local-cluster.sh" status > /dev/null 2>&1; then
    say "local cluster already running: using it, leaving it running"
else
    started=1
    t0=$SECONDS
    "$here/local-cluster.sh" start || fail "local-cluster.sh start failed"
    say "local cluster started in $((SECONDS - t0))s"
fi
sinfo -N -o '%N %T %c %m' | sed 's/^/test-array:   /'

# --- submit ------------------------------------------------------------------
# Two submissions, queued together: the image in $shards shards (the test
# proper) and a small turntable split by frame.
submit() { # NAME N render options... -> sets ${NAME}_render, ${NAME}_assemble
    local name=$1 n=$2 ids r a
    shift 2
    "$here/submit.sh" "$work/s.cdv" "$work/$name" "$n" "$@" > "$work/$name.submit" ||
        fail "submit.sh for the $name failed"
    sed 's/^/  /' "$work/$name.submit"
    ids=$(tail -n 1 "$work/$name.submit")
    read -r r a <<< "$ids"
    [[ $r =~ ^[0-9]+$ && $a =~ ^[0-9]+$ ]] || fail "unexpected submit.sh output: $ids"
    printf -v "${name}_render" %s "$r"
    printf -v "${name}_assemble" %s "$a"
}
image_render='' image_assemble='' turntable_render='' turntable_assemble=''
t_submit=$SECONDS
say "submitting the image: submit.sh $work/s.cdv $work/image $shards ${render_args[*]}"
submit image "$shards" "${render_args[@]}"
say "submitting the turntable: submit.sh $work/s.cdv $work/turntable $tt_shards ${tt_args[*]}"
submit turntable "$tt_shards" "${tt_args[@]}"
say "submitting the prep: submit-prep.sh $work/ct.json $work/ct.cdv 4 ${prep_args[*]}"
"$here/submit-prep.sh" "$work/ct.json" "$work/ct.cdv" 4 "${prep_args[@]}" > "$work/prep.submit" ||
    fail "submit-prep.sh failed"
sed 's/^/  /' "$work/prep.submit"
read -r prep_pass1 prep_pass2 prep_merge <<< "$(tail -n 1 "$work/prep.submit")"
[[ $prep_pass1 =~ ^[0-9]+$ && $prep_pass2 =~ ^[0-9]+$ && $prep_merge =~ ^[0-9]+$ ]] ||
    fail "unexpected submit-prep.sh output: $(tail -n 1 "$work/prep.submit")"
say "image: render array job $image_render, assemble job $image_assemble; turntable: render array job $turntable_render, check job $turntable_assemble; prep: pass 1 $prep_pass1, pass 2 $prep_pass2, merge $prep_merge"

job_field() { # JOBLINE FIELD -> value of FIELD= in a `scontrol show job -o` line
    tr ' ' '\n' <<< "$1" | sed -n "s/^$2=//p" | head -n 1
}
final() { # JOBID -> its state once finished (UNKNOWN if slurmctld forgot it), nothing while it runs
    local st out rc=0
    out=$(scontrol show job -o "$1" 2>&1) || rc=$?
    if [ "$rc" != 0 ]; then
        # A forgotten job is finished; any other failure (slurmctld slow to
        # answer under load) says nothing, and the loop asks again.
        case $out in *"Invalid job id"*) echo UNKNOWN ;; esac
        return 0
    fi
    st=$(job_field "$out" JobState)
    case $st in
        "") echo UNKNOWN ;;
        PENDING | RUNNING | CONFIGURING | COMPLETING | SUSPENDED | REQUEUED | RESIZING) ;;
        *) echo "$st" ;;
    esac
}
while :; do
    a=$(final "$image_assemble")
    b=$(final "$turntable_assemble")
    c=$(final "$prep_merge")
    [ -z "$a" ] || [ -z "$b" ] || [ -z "$c" ] || break
    [ $((SECONDS - t_submit)) -lt "$timeout" ] || {
        squeue >&2 || true
        scancel "$image_render" "$image_assemble" "$turntable_render" "$turntable_assemble" \
            "$prep_pass1" "$prep_pass2" "$prep_merge" 2>/dev/null || true
        fail "jobs not finished after ${timeout}s"
    }
    sleep 1
done
t_jobs=$((SECONDS - t_submit))

report() { # NAME RENDER_JOB ASSEMBLE_JOB TASKS -> prints the jobs, fails unless all COMPLETED
    local name=$1 render_job=$2 assemble_job=$3 tasks=$4 jobs line id task jstate ok=1 rows=() f
    jobs=$(scontrol show job -o "$render_job"; scontrol show job -o "$assemble_job")
    say "$name jobs (scontrol show job):"
    printf 'test-array:   %-12s %-10s %-6s %-9s %-5s %-19s %s\n' JOB STATE NODE RUNTIME EXIT START END
    while read -r line; do
        [ -n "$line" ] || continue
        id=$(job_field "$line" JobId)
        task=$(job_field "$line" ArrayTaskId)
        jstate=$(job_field "$line" JobState)
        [ "$jstate" = COMPLETED ] || ok=0
        [ -z "$task" ] || id=${render_job}_$task
        rows+=("$(printf 'test-array:   %-12s %-10s %-6s %-9s %-5s %-19s %s' \
            "$id" "$jstate" "$(job_field "$line" NodeList)" "$(job_field "$line" RunTime)" \
            "$(job_field "$line" ExitCode)" "$(job_field "$line" StartTime)" "$(job_field "$line" EndTime)")")
    done <<< "$jobs"
    printf '%s\n' "${rows[@]}" | sort -V
    [ "$(grep -c 'JobState=' <<< "$jobs")" -eq $((tasks + 1)) ] || ok=0
    say "$name task logs:"
    grep -h 'done on' "$work/$name"/logs/render.*.out | sort -V | sed 's/^render-array: /test-array:   /' || true
    grep -hs '^assemble: \(wrote\|all\)' "$work/$name"/logs/assemble.*.out | sed 's/^assemble: /test-array:   /' || true
    if [ $ok != 1 ]; then
        for f in "$work/$name"/logs/*.out; do
            echo "----- $f" >&2
            tail -n 20 "$f" >&2
        done
        fail "a $name job did not complete"
    fi
}
report image "$image_render" "$image_assemble" "$shards"
report turntable "$turntable_render" "$turntable_assemble" "$tt_shards"
say "prep jobs (scontrol show job):"
prep_jobs=$(scontrol show job -o "$prep_pass1"; scontrol show job -o "$prep_pass2"; scontrol show job -o "$prep_merge")
while read -r line; do
    [ -n "$line" ] || continue
    printf 'test-array:   %-8s %-6s %-10s %-9s %s\n' "$(job_field "$line" JobId)" \
        "$(job_field "$line" ArrayTaskId)" "$(job_field "$line" JobState)" \
        "$(job_field "$line" RunTime)" "$(job_field "$line" JobName)"
done <<< "$prep_jobs"
if [ "$(grep -c 'JobState=COMPLETED' <<< "$prep_jobs")" != 9 ]; then
    for f in "$work"/ct.cdv.logs/*.out; do
        echo "----- $f" >&2
        tail -n 20 "$f" >&2
    done
    fail "a prep job did not complete (expected 4 + 4 tasks and the merge)"
fi
grep -h 'done on\|prep-merge: wrote' "$work"/ct.cdv.logs/*.out | sort -V | sed 's/^/test-array:   /' || true
say "all jobs done ${t_jobs}s after the first submission"

# --- compare -----------------------------------------------------------------
t0=$(date +%s.%N)
"$CDVOL" render "$work/s.cdv" -o "$work/single.png" "${render_args[@]}" > /dev/null || fail "single-process render failed"
t1=$(date +%s.%N)
say "single-process render: $(awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.2f", b - a }')s, all cores"
[ -s "$work/image/out.png" ] || fail "no assembled $work/image/out.png"
cmp "$work/image/out.png" "$work/single.png" ||
    fail "assembled PNG differs from the single-process render"
say "image: assembled out.png == single-process render ($(stat -c %s "$work/single.png") bytes, sha256 $(sha256sum < "$work/single.png" | cut -c1-16))"

mkdir "$work/tt-single"
"$CDVOL" render "$work/s.cdv" -o "$work/tt-single/frame.png" "${tt_args[@]}" > /dev/null ||
    fail "single-process turntable failed"
n_frames=0
for f in "$work/tt-single"/frame.*.png; do
    cmp "$f" "$work/turntable/$(basename "$f")" || fail "turntable frame $(basename "$f") differs"
    n_frames=$((n_frames + 1))
done
[ $n_frames = "$tt_frames" ] || fail "single-process turntable wrote $n_frames frames, expected $tt_frames"
say "turntable: all $tt_frames frames == single-process turntable"
[ -s "$work/ct.cdv" ] || fail "no merged $work/ct.cdv"
cmp "$work/ct.cdv" "$work/ct-single.cdv" || fail "the sharded prep's file differs from the single-process prep's"
[ ! -e "$work/ct.cdv.parts" ] || fail "the merge left $work/ct.cdv.parts behind"
say "prep: merged ct.cdv == single-process prep ($(stat -c %s "$work/ct.cdv") bytes)"
say "PASS ($shards-shard image: jobs $image_render/$image_assemble; $tt_frames-frame turntable in $tt_shards shards: jobs $turntable_render/$turntable_assemble; 4-shard prep: jobs $prep_pass1/$prep_pass2/$prep_merge)"
