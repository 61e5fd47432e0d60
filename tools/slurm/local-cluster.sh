#!/usr/bin/env bash
# A real one-node Slurm cluster on this machine, from Debian's packages,
# for testing the sbatch scripts beside this file (tools/slurm/test-array.sh).
#
# usage: tools/slurm/local-cluster.sh start|stop|status|env|install
#
#   start   installs slurm-wlm and munge with apt-get if they are missing,
#           creates the munge key if it is missing, starts a private munged,
#           writes a minimal slurm.conf, starts slurmctld and slurmd as plain
#           daemons (no systemd) and waits until `sinfo` shows the node idle.
#           Does nothing if this cluster is already up.
#   stop    cancels the cluster's jobs and stops exactly the daemons that
#           `start` started (their pid files, checked against their command
#           lines), munged included.
#   status  shows the daemons, sinfo and squeue; exit 0 if the node is up,
#           3 if the cluster is not running.
#   env     prints `export SLURM_CONF=...`: eval "$(local-cluster.sh env)"
#           lets sbatch, squeue, sinfo ... talk to this cluster.
#   install only installs the packages `start` would (.ci/run does it in
#           the background while cargo builds).
#
# Everything (config, state, spool, logs, pid files, munge socket) lives in
# one private directory, $CDVOL_SLURM_DIR (default /tmp/cdvol-slurm); nothing
# is written under /etc except the munge key when it is missing. The clients
# find the cluster through SLURM_CONF=$CDVOL_SLURM_DIR/slurm.conf (there is no
# /etc/slurm/slurm.conf, and this script never writes one).
#
# Environment:
#   CDVOL_SLURM_DIR        private directory            [/tmp/cdvol-slurm]
#   CDVOL_SLURM_TIMEOUT    seconds to wait for the node [60]
#   CDVOL_SLURMCTLD_PORT   slurmctld port               [6817]
#   CDVOL_SLURMD_PORT      slurmd port                  [6818]
#   MUNGE_KEY              munge key                    [/etc/munge/munge.key]
#
# Must run as root: the daemons run as root (SlurmUser=root) and munged as
# the `munge` user, as Debian packages them.
set -euo pipefail

dir=${CDVOL_SLURM_DIR:-/tmp/cdvol-slurm}
timeout=${CDVOL_SLURM_TIMEOUT:-60}
ctld_port=${CDVOL_SLURMCTLD_PORT:-6817}
slurmd_port=${CDVOL_SLURMD_PORT:-6818}
munge_key=${MUNGE_KEY:-/etc/munge/munge.key}

conf=$dir/slurm.conf
munge_dir=$dir/munge
munge_socket=$munge_dir/munge.socket.2
munge_pid=$munge_dir/munged.pid
ctld_pid=$dir/run/slurmctld.pid
slurmd_pid=$dir/run/slurmd.pid
logs=$dir/log

export SLURM_CONF=$conf

die() { echo "local-cluster: error: $*" >&2; exit 1; }
say() { echo "local-cluster: $*" >&2; }

# The pid in FILE if that process is alive and its command line names NAME and
# this cluster's directory (so a stale pid file whose pid was reused by some
# other process is never trusted); nothing otherwise.
live_pid() { # FILE NAME
    local file=$1 name=$2 pid cmd
    [ -s "$file" ] || return 0
    pid=$(tr -dc '0-9' < "$file")
    [ -n "$pid" ] && [ -r "/proc/$pid/cmdline" ] || return 0
    cmd=$(tr '\0' ' ' < "/proc/$pid/cmdline" 2>/dev/null) || return 0
    case $cmd in
        *"$name"*"$dir"*) echo "$pid" ;;
    esac
}

# Node state as sinfo prints it (idle, mixed, allocated, idle*, down*, ...),
# empty if slurmctld does not answer.
node_state() {
    timeout 10 sinfo -h -N -n "$host" -o %T 2>/dev/null | head -n 1 || true
}

node_up() {
    case $(node_state) in
        idle | mixed | allocated | completing) return 0 ;;
        *) return 1 ;;
    esac
}

show_logs() {
    local f
    for f in "$logs/slurmctld.log" "$logs/slurmd.log" "$munge_dir/munged.log"; do
        [ -f "$f" ] || continue
        echo "----- last lines of $f" >&2
        tail -n 25 "$f" >&2
    done
}

stop_pid() { # PID NAME
    local pid=$1 name=$2
    kill -TERM "$pid" 2>/dev/null || return 0
    for _ in $(seq 50); do
        kill -0 "$pid" 2>/dev/null || { say "stopped $name (pid $pid)"; return 0; }
        sleep 0.2
    done
    say "$name (pid $pid) ignored SIGTERM for 10 s; sending SIGKILL"
    kill -KILL "$pid" 2>/dev/null || true
}

host=$(hostname -s)

install_packages() {
    local missing=()
    command -v munged > /dev/null || missing+=(munge)
    command -v slurmctld > /dev/null || missing+=(slurmctld)
    command -v slurmd > /dev/null || missing+=(slurmd)
    command -v sbatch > /dev/null || missing+=(slurm-client)
    [ ${#missing[@]} -eq 0 ] && return 0
    say "installing slurm-wlm munge (missing: ${missing[*]})"
    command -v apt-get > /dev/null || die "slurm/munge missing and no apt-get; install ${missing[*]} by hand"
    # Without systemd the packages' scripts would try to start the stock
    # daemons (with no /etc/slurm/slurm.conf): forbid that for the install
    # unless the machine already has a policy.
    local policy=/usr/sbin/policy-rc.d made_policy=0
    if [ ! -e "$policy" ]; then
        printf '#!/bin/sh\nexit 101\n' > "$policy" && chmod 755 "$policy" && made_policy=1
    fi
    local rc=0
    { apt-get -o DPkg::Lock::Timeout=600 update -q && DEBIAN_FRONTEND=noninteractive apt-get -o DPkg::Lock::Timeout=600 install -y -q slurm-wlm munge; } >&2 || rc=$?
    [ $made_policy = 1 ] && rm -f "$policy"
    [ $rc = 0 ] || die "apt-get install slurm-wlm munge failed (exit $rc)"
}

ensure_munge_key() {
    [ -s "$munge_key" ] && return 0
    say "creating munge key $munge_key"
    mkdir -p "$(dirname "$munge_key")"
    if command -v mungekey > /dev/null; then
        mungekey --create --keyfile="$munge_key"
    else
        dd if=/dev/urandom of="$munge_key" bs=1024 count=1 status=none
    fi
    chown munge:munge "$munge_key" "$(dirname "$munge_key")"
    chmod 0400 "$munge_key"
}

munge_works() {
    [ -S "$munge_socket" ] && munge -S "$munge_socket" -n 2>/dev/null | unmunge -S "$munge_socket" > /dev/null 2>&1
}

start_munged() {
    if munge_works; then
        say "munged already answering on $munge_socket"
        return 0
    fi
    # munged refuses a key file not owned by the user it runs as, so it runs
    # as `munge` (the owner Debian gives /etc/munge/munge.key), and it wants
    # every client to be able to reach the socket: the socket directory must
    # be owned by munge and world-searchable (0755). A private socket keeps
    # this munged apart from any system one (/run/munge); slurm.conf points
    # Slurm at it with AuthInfo=socket=...
    mkdir -p "$munge_dir"
    chown munge:munge "$munge_dir"
    chmod 0755 "$munge_dir"
    rm -f "$munge_socket" "$munge_socket.lock" "$munge_pid"
    runuser -u munge -- munged --socket="$munge_socket" --key-file="$munge_key" \
        --pid-file="$munge_pid" --log-file="$munge_dir/munged.log" \
        --seed-file="$munge_dir/munged.seed" ||
        { show_logs; die "munged did not start (log above)"; }
    for _ in $(seq 50); do
        munge_works && { say "started munged (pid $(cat "$munge_pid"))"; return 0; }
        sleep 0.2
    done
    show_logs
    die "munged started but does not answer on $munge_socket"
}

write_conf() {
    local cpus mem_mb
    cpus=$(nproc)
    # RealMemory a bit under what is free now (90% of MemAvailable): a node
    # claiming more memory than slurmd finds is drained ("Low RealMemory").
    mem_mb=$(awk '/^MemAvailable:/ { printf "%d", $2 / 1024 * 0.9 }' /proc/meminfo)
    [ "${mem_mb:-0}" -gt 0 ] || mem_mb=1024
    mkdir -p "$dir/state" "$dir/spool/slurmd" "$dir/run" "$logs"
    cat > "$conf.tmp" << EOF
# Written by tools/slurm/local-cluster.sh: a one-node cluster on $host.
ClusterName=cdvol-local
# Clients and slurmd reach slurmctld on the loopback address, whatever the
# host name resolves to.
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$ctld_port
SlurmdPort=$slurmd_port
SlurmUser=root
SlurmdUser=root

AuthType=auth/munge
CredType=cred/munge
# The private munged started by local-cluster.sh.
AuthInfo=socket=$munge_socket

StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool/slurmd
SlurmctldPidFile=$ctld_pid
SlurmdPidFile=$slurmd_pid
SlurmctldLogFile=$logs/slurmctld.log
SlurmdLogFile=$logs/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info

# No cgroups. This sandbox has no systemd and a hybrid cgroup tree (v1
# controllers plus a v2 mount at /sys/fs/cgroup/unified). Tried here:
#  - CgroupPlugin=cgroup/v2: slurmd dies at start, "fatal: Hybrid mode is
#    not supported"; on v2-only hosts it wants a delegated subtree, which
#    systemd normally makes for slurmd.service.
#  - cgroup v1 (autodetect) with proctrack/cgroup + task/cgroup works in this
#    sandbox, but writes /sys/fs/cgroup/{cpuset,memory,freezer}/slurm_<host>
#    directories that outlive the daemons, and it cannot work where
#    /sys/fs/cgroup is mounted read-only (as in many containers).
# proctrack/linuxproc tracks a job's processes through /proc parent links
# and task/none does no binding, so nothing depends on the host's cgroup
# layout and nothing is left behind; jobacct_gather/none keeps the samplers
# out too. Consequence: no memory or core confinement (a task sees every
# core, which is why render-array.sbatch passes --threads from the
# allocation).
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none

# No accounting (no slurmdbd, so no sacct): job state comes from
# scontrol show job, which keeps finished jobs for MinJobAge seconds.
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MinJobAge=3600

SchedulerType=sched/backfill
# Cancel jobs whose dependency can never be met (e.g. the assemble step
# after a failed render task) instead of leaving them pending forever.
DependencyParameters=kill_invalid_depend
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
# slurmd still loads every MPI plugin at start and logs "can not load PMIx
# library" errors for mpi/pmix (libpmix is not installed): harmless.
MpiDefault=none
# A node that was down (e.g. slurmd restarted) comes back by itself.
ReturnToService=2
SlurmdTimeout=60

NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem_mb State=UNKNOWN
PartitionName=local Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
    mv "$conf.tmp" "$conf"
}

cmd_start() {
    [ "$(id -u)" = 0 ] || die "run as root (the daemons run as root, munged as munge)"
    if [ -n "$(live_pid "$ctld_pid" slurmctld)" ] && [ -n "$(live_pid "$slurmd_pid" slurmd)" ] && node_up; then
        say "already running ($host $(node_state)); SLURM_CONF=$conf"
        return 0
    fi
    install_packages
    ensure_munge_key
    mkdir -p "$dir"
    start_munged
    write_conf

    local started=()
    if [ -z "$(live_pid "$ctld_pid" slurmctld)" ]; then
        slurmctld -f "$conf" || { show_logs; cmd_stop_quiet; die "slurmctld -f $conf failed"; }
        started+=(slurmctld)
    else
        scontrol reconfigure > /dev/null 2>&1 || true
    fi
    if [ -z "$(live_pid "$slurmd_pid" slurmd)" ]; then
        slurmd -f "$conf" || { show_logs; cmd_stop_quiet; die "slurmd -f $conf failed"; }
        started+=(slurmd)
    fi
    [ ${#started[@]} -eq 0 ] || say "started ${started[*]} with $conf"

    local t0=$SECONDS
    until node_up; do
        if [ $((SECONDS - t0)) -ge "$timeout" ]; then
            echo "local-cluster: node $host not idle after ${timeout}s; state: '$(node_state)'" >&2
            timeout 10 scontrol show node "$host" >&2 || true
            show_logs
            cmd_stop_quiet
            die "cluster did not come up (daemons stopped; logs above, all logs in $logs)"
        fi
        # A node left down/drained by an earlier run: ReturnToService=2 only
        # acts on registration, so ask once more.
        case $(node_state) in
            down* | drain*) scontrol update nodename="$host" state=resume > /dev/null 2>&1 || true ;;
        esac
        sleep 1
    done
    say "up after $((SECONDS - t0))s: node $host $(node_state), $(nproc) CPUs; SLURM_CONF=$conf"
}

cmd_stop_quiet() { cmd_stop > /dev/null 2>&1 || true; }

cmd_stop() {
    local pid any=0
    if [ -n "$(live_pid "$ctld_pid" slurmctld)" ]; then
        # Cancel what is still queued or running, so no job step outlives
        # the daemons (slurmstepd would otherwise keep running).
        local jobs
        jobs=$(timeout 10 squeue -h -o %A 2>/dev/null | tr '\n' ' ' || true)
        if [ -n "${jobs// /}" ]; then
            say "cancelling jobs: $jobs"
            # shellcheck disable=SC2086
            timeout 10 scancel $jobs 2>/dev/null || true
            for _ in $(seq 20); do
                [ -z "$(timeout 10 squeue -h -o %A 2>/dev/null)" ] && break
                sleep 0.5
            done
        fi
    fi
    pid=$(live_pid "$slurmd_pid" slurmd)
    [ -z "$pid" ] || { stop_pid "$pid" slurmd; any=1; }
    pid=$(live_pid "$ctld_pid" slurmctld)
    [ -z "$pid" ] || { stop_pid "$pid" slurmctld; any=1; }
    pid=$(live_pid "$munge_pid" munged)
    [ -z "$pid" ] || { stop_pid "$pid" munged; any=1; }
    rm -f "$slurmd_pid" "$ctld_pid"
    [ $any = 1 ] || say "nothing to stop (no live daemons from $dir)"
}

cmd_status() {
    local pid name file rc=0
    for name in munged slurmctld slurmd; do
        case $name in
            munged) file=$munge_pid ;;
            slurmctld) file=$ctld_pid ;;
            slurmd) file=$slurmd_pid ;;
        esac
        pid=$(live_pid "$file" "$name")
        if [ -n "$pid" ]; then
            printf '%-10s running (pid %s)\n' "$name" "$pid"
        else
            printf '%-10s not running\n' "$name"
        fi
    done
    echo "SLURM_CONF=$conf"
    if [ -z "$(live_pid "$ctld_pid" slurmctld)" ]; then
        return 3
    fi
    timeout 10 sinfo -N -l || rc=$?
    timeout 10 squeue || rc=$?
    node_up || rc=1
    return $rc
}

case ${1:-} in
    start) cmd_start ;;
    stop) cmd_stop ;;
    status) cmd_status ;;
    env) echo "export SLURM_CONF=$conf" ;;
    install) install_packages ;;
    *) echo "usage: $0 start|stop|status|env|install" >&2; exit 2 ;;
esac
