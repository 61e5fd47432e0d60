#!/usr/bin/env bash
# Submits a sharded cdvol prep of one volume to Slurm (docs/SCALE.md):
# pass 1 as an array of N tasks, pass 2 as an array after it
# (--dependency=afterok), and the merge after that. The packed file is
# the one a single `cdvol prep` writes, byte for byte.
#
# usage: tools/slurm/submit-prep.sh INPUT OUT N [prep options...]
#
#   INPUT  the volume, on a file system every node sees
#   OUT    the packed file to write; its parts go to OUT.parts/ and the
#          logs to OUT.logs/
#   N      number of shards (at most the volume's brick layers)
#   prep options as for `cdvol prep` (not -o, --shard, --pass, --parts)
#
# Environment:
#   CDVOL          cdvol binary on the shared file system [cdvol on PATH,
#                  else target/release/cdvol of this checkout]
#   CPUS_PER_TASK  CPUs per prep task [1]
#   KEEP_PARTS=1   keep OUT.parts after the merge
#   SBATCH_PARTITION, SBATCH_ACCOUNT, SBATCH_TIMELIMIT ... read by sbatch
#
# Prints the job ids, and on its last line "PASS1_JOB PASS2_JOB MERGE_JOB".
set -euo pipefail

die() { echo "submit-prep: error: $*" >&2; exit 1; }

[ $# -ge 3 ] || { sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//' >&2; exit 2; }
input=$1 out=$2 n=$3
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
[ -e "$input" ] || die "input '$input' does not exist"
INPUT=$(realpath "$input")
out_dir=$(dirname "$out")
[ -d "$out_dir" ] || die "the output's directory '$out_dir' does not exist"
OUT=$(realpath "$out_dir")/$(basename "$out")
for a in "$@"; do
    case $a in
        -o | --output | --output=* | -o?* | --shard | --shard=* | --pass | --pass=* | --parts | --parts=*)
            die "prep options must not include '$a' (submit-prep.sh sets the output, shard, pass and parts)" ;;
    esac
done
# Old parts of another run would be refused by name at the merge; say so now.
shopt -s nullglob
old=("$OUT.parts"/shard-*)
[ ${#old[@]} -eq 0 ] || die "$OUT.parts already holds ${#old[@]} files of an earlier run; remove them or choose another OUT"
# A mistyped option fails here, not in N tasks: clap parses every argument
# before it acts on the trailing --help.
"$CDVOL" prep "$INPUT" -o "$OUT" --shard 0/"$n" --pass 1 "$@" --help > /dev/null 2>&1 ||
    die "'cdvol prep' rejects these options: $* (try: $CDVOL prep --help)"
mkdir -p "$OUT.logs" "$OUT.parts"
export CDVOL INPUT OUT N=$n
cpus=${CPUS_PER_TASK:-1}
common=(--parsable --cpus-per-task="$cpus" --chdir="$OUT.logs")
pass1=$(PASS=1 sbatch "${common[@]}" --array="0-$((n - 1))" --job-name=cdvol-prep1 \
    --output="$OUT.logs/pass1.%A_%a.out" "$here/prep-array.sbatch" "$@") ||
    die "sbatch of pass 1 failed"
pass1=${pass1%%;*}
echo "submit-prep: pass 1 array job $pass1: $n tasks, $cpus CPU(s) each"
pass2=$(PASS=2 sbatch "${common[@]}" --array="0-$((n - 1))" --job-name=cdvol-prep2 \
    --dependency="afterok:$pass1" --output="$OUT.logs/pass2.%A_%a.out" \
    "$here/prep-array.sbatch" "$@") || {
    scancel "$pass1" 2>/dev/null || true
    die "sbatch of pass 2 failed (pass 1 $pass1 cancelled)"
}
pass2=${pass2%%;*}
echo "submit-prep: pass 2 array job $pass2 after afterok:$pass1"
merge=$(sbatch --parsable --job-name=cdvol-prep-merge --chdir="$OUT.logs" \
    --dependency="afterok:$pass2" --output="$OUT.logs/merge.%j.out" \
    "$here/prep-merge.sbatch") || {
    scancel "$pass1" "$pass2" 2>/dev/null || true
    die "sbatch of the merge failed (passes $pass1 and $pass2 cancelled)"
}
merge=${merge%%;*}
echo "submit-prep: merge job $merge after afterok:$pass2 -> $OUT"
echo "submit-prep: logs in $OUT.logs/; watch with: squeue -j $pass1,$pass2,$merge"
echo "$pass1 $pass2 $merge"
