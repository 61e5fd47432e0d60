#!/usr/bin/env bash
# Submits a sharded cdvol render to Slurm: an array job of N render tasks
# (render-array.sbatch, one shard each), then the assemble step
# (assemble.sbatch) with --dependency=afterok on the whole array.
#
# usage: tools/slurm/submit.sh VOL OUT_DIR N [render options...]
#
#   VOL      packed volume (.cdv) on a file system every node sees
#   OUT_DIR  output directory on that file system (created if missing): it
#            gets part.K.cdvpart, out.png, stats.json and logs/
#   N        number of shards (array tasks)
#   render options as for `cdvol render`, e.g. --width 2048 --height 2048
#            --view 30,20 --mode surface (not -o, --shard, --stats). With
#            --frames F (F > 1) the job renders a turntable instead: shard K
#            writes frames f % N == K as OUT_DIR/frame.FFFF.png, and the
#            assemble step only checks that all F are there.
#
# Environment:
#   CDVOL          cdvol binary on the shared file system [cdvol on PATH, else
#                  target/release/cdvol of this checkout]
#   CPUS_PER_TASK  CPUs per render task, also its --threads [1]
#   MAX_PARALLEL   run at most this many render tasks at once (--array=...%M)
#   OUT, STATS, KEEP_PARTS   passed to assemble.sbatch
#   SBATCH_PARTITION, SBATCH_ACCOUNT, SBATCH_TIMELIMIT, SBATCH_MEM_PER_NODE,
#   SBATCH_QOS ...  read by sbatch itself for both jobs
#
# Prints the job ids, and on its last line "RENDER_JOB ASSEMBLE_JOB"
# (JOB=$(submit.sh ... | tail -n 1)).
set -euo pipefail

die() { echo "submit: error: $*" >&2; exit 1; }

[ $# -ge 3 ] || { sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//' >&2; exit 2; }
vol=$1 out_dir=$2 n=$3
shift 3
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)

command -v sbatch > /dev/null || die "sbatch not found (not on a Slurm login node? for a local test: tools/slurm/local-cluster.sh start)"
[[ $n =~ ^[1-9][0-9]*$ ]] || die "N='$n' is not a positive integer"

if [ -z "${CDVOL:-}" ]; then
    CDVOL=$(command -v cdvol || true)
    [ -n "$CDVOL" ] || CDVOL=$here/../../target/release/cdvol
fi
[ -x "$CDVOL" ] || die "no cdvol binary at '$CDVOL' (set CDVOL, or cargo build --release)"
CDVOL=$(realpath "$CDVOL")
[ -r "$vol" ] || die "volume '$vol' not readable"
VOL=$(realpath "$vol")
mkdir -p "$out_dir/logs" || die "cannot create '$out_dir/logs'"
OUT_DIR=$(realpath "$out_dir")
N=$n

# Old parts would be silently mixed into (or, with another N, rejected by)
# this render's assemble step.
shopt -s nullglob
old=("$OUT_DIR"/part.*.cdvpart "$OUT_DIR"/frame.*.png)
[ ${#old[@]} -eq 0 ] ||
    die "$OUT_DIR already holds ${#old[@]} part or frame files from an earlier run; remove them (rm $OUT_DIR/part.*.cdvpart $OUT_DIR/frame.*.png) or choose another OUT_DIR"

# Check the render options once here rather than in N failing tasks, and
# make a transfer-function path absolute (the tasks run in OUT_DIR).
args=()
FRAMES=1
while [ $# -gt 0 ]; do
    case $1 in
        --frames) FRAMES=${2:-} ;;
        --frames=*) FRAMES=${1#--frames=} ;;
    esac
    case $1 in
        -o | --output | --output=* | -o?* | --shard | --shard=* | --stats | --stats=*)
            die "render options must not include '$1' (submit.sh sets the output and shard; assemble writes \$OUT_DIR/stats.json)" ;;
        --tf)
            [ $# -ge 2 ] || die "--tf needs a file"
            [ -r "$2" ] || die "--tf file '$2' not readable"
            args+=(--tf "$(realpath "$2")")
            shift 2
            continue ;;
        --tf=*)
            [ -r "${1#--tf=}" ] || die "--tf file '${1#--tf=}' not readable"
            args+=(--tf "$(realpath "${1#--tf=}")") ;;
        *) args+=("$1") ;;
    esac
    shift
done
set -- "${args[@]}"
[[ $FRAMES =~ ^[1-9][0-9]*$ ]] || die "--frames '$FRAMES' is not a positive integer"
[ "$FRAMES" = 1 ] || [ "$N" -le "$FRAMES" ] ||
    die "N=$N shards for $FRAMES frames: shards split a turntable by frame, so at most $FRAMES have work"
# Catches a mistyped option or value before anything is queued: clap parses
# every argument before it acts on the trailing --help.
"$CDVOL" render "$VOL" -o "$OUT_DIR/part.0.cdvpart" --shard 0/"$N" "$@" --help > /dev/null 2>&1 ||
    die "'cdvol render' rejects these options: $* (try: $CDVOL render --help)"

# The jobs see this environment (sbatch --export=ALL, the default). The render
# options travel as script arguments, so RENDER_ARGS must not add others.
export CDVOL VOL OUT_DIR N FRAMES
export RENDER_ARGS=
cpus=${CPUS_PER_TASK:-1}
array=0-$((N - 1))${MAX_PARALLEL:+%$MAX_PARALLEL}

render_job=$(sbatch --parsable --array="$array" --cpus-per-task="$cpus" \
    --job-name=cdvol-render --chdir="$OUT_DIR" \
    --output="$OUT_DIR/logs/render.%A_%a.out" \
    "$here/render-array.sbatch" "$@") || die "sbatch of the render array failed"
render_job=${render_job%%;*}
echo "submit: render array job $render_job: $N tasks ($array), $cpus CPU(s) each, parts in $OUT_DIR"

assemble_job=$(sbatch --parsable --dependency="afterok:$render_job" \
    --job-name=cdvol-assemble --chdir="$OUT_DIR" \
    --output="$OUT_DIR/logs/assemble.%j.out" \
    "$here/assemble.sbatch") || {
    scancel "$render_job" 2>/dev/null || true
    die "sbatch of the assemble step failed (render array $render_job cancelled)"
}
assemble_job=${assemble_job%%;*}
if [ "$FRAMES" -gt 1 ]; then
    echo "submit: check job $assemble_job after afterok:$render_job -> $OUT_DIR/frame.0000.png .. $(printf 'frame.%04d.png' $((FRAMES - 1)))"
else
    echo "submit: assemble job $assemble_job after afterok:$render_job -> ${OUT:-$OUT_DIR/out.png}"
fi
echo "submit: logs in $OUT_DIR/logs/; watch with: squeue -j $render_job,$assemble_job"
echo "$render_job $assemble_job"
