#!/usr/bin/env bash
# A real SLURM cluster of three nodes on this one machine, everything under one folder, for the
# tests in tests/slurm_real.rs and for trying `tessera slurm` by hand (docs/cluster.md).
#
#   scripts/slurm_cluster.sh start DIR [BASE_PORT [FIRST_JOB_ID]]
#       slurmctld on BASE_PORT (17000), the nodes on BASE_PORT+1 .. +3; job ids from FIRST_JOB_ID
#       (1), which fixes the port `tessera slurm` derives for the first job's steps
#   scripts/slurm_cluster.sh stop DIR                # stops every daemon that start began
#   SLURM_CONF=DIR/slurm.conf srun -N3 -n3 hostname  # once started
#
# Needs root and Debian's `slurmd slurmctld slurm-client munge` (.ci/run installs them). Nothing
# outside DIR is written or read but the binaries and /etc/passwd: the munge key, the sockets,
# the state, the spool and the logs are all DIR's, so several clusters (on other ports) can run
# at once and none of them touches the machine's own SLURM or munge, if any.
#
# The nodes are n1, n2 and n3, all at 127.0.0.1 with ports of their own (Debian builds slurmd
# for several per host, `slurmd -N NAME`). n1 must resolve to a loopback address, because
# tessera's peers dial task 0 by its node's name: `127.0.0.1 n1 n2 n3` in /etc/hosts, which
# .ci/run writes and start asks for. (`localhost` cannot be a node name here: SLURM takes a
# cluster whose first node is `localhost` for a one-node cluster and refuses a second node.)
set -euo pipefail

usage() {
    echo "usage: $0 start DIR [BASE_PORT [FIRST_JOB_ID]] | stop DIR" >&2
    exit 2
}

[ $# -ge 2 ] || usage
action=$1
dir=$2

# Each daemon's pid file.
pid_files() {
    echo "$dir/run/slurmd-n1.pid $dir/run/slurmd-n2.pid $dir/run/slurmd-n3.pid"
    echo "$dir/run/slurmctld.pid $dir/munge/munged.pid"
}

stop() {
    local file pid pids=()
    # Steps still running (a test that failed half-way) would outlive their slurmd: cancel the
    # cluster's jobs first, while its controller still answers, and give them a moment.
    if [ -s "$dir/run/slurmctld.pid" ] && [ -s "$dir/slurm.conf" ] &&
        SLURM_CONF="$dir/slurm.conf" scancel --quiet --user=root 2>/dev/null; then
        for _ in $(seq 50); do
            [ -z "$(SLURM_CONF="$dir/slurm.conf" squeue -h -o %i 2>/dev/null)" ] && break
            sleep 0.1
        done
    fi
    for file in $(pid_files); do
        [ -s "$file" ] || continue
        pid=$(cat "$file")
        # A pid file outlives its daemon; the name check keeps us from signalling a stranger
        # that was given the same pid since.
        if kill -0 "$pid" 2>/dev/null && grep -qE 'slurm|munge' "/proc/$pid/comm"; then
            pids+=("$pid")
        fi
        rm -f "$file"
    done
    [ ${#pids[@]} -gt 0 ] || return 0
    # Each daemon takes a second or two to end, so they are all told at once; none of them
    # needs another to shut down cleanly.
    kill -TERM "${pids[@]}" 2>/dev/null || true
    for _ in $(seq 100); do
        kill -0 "${pids[@]}" 2>/dev/null || break
        sleep 0.1
    done
    for pid in "${pids[@]}"; do
        kill -0 "$pid" 2>/dev/null && kill -KILL "$pid"
    done
    return 0
}

# Why this cluster cannot start, on stderr, with the log that says more; then exit 1.
fail() {
    echo "slurm_cluster: $1" >&2
    if [ -n "${2:-}" ] && [ -s "$2" ]; then
        echo "--- last lines of $2:" >&2
        tail -n 20 "$2" >&2
    fi
    stop
    exit 1
}

start() {
    local base=${1:-17000} first_job=${2:-1}
    [ "$(id -u)" = 0 ] || fail "needs root (the daemons run as root, munged as the munge user)"
    local tool
    for tool in munged mungekey slurmctld slurmd srun sinfo runuser; do
        command -v "$tool" >/dev/null ||
            fail "$tool is not installed (apt-get install slurmd slurmctld slurm-client munge)"
    done
    getent passwd munge >/dev/null || fail "no munge user (the munge package makes one)"
    local file
    for file in $(pid_files); do
        # Not `fail`, which would stop the cluster that is running there.
        if [ -s "$file" ] && kill -0 "$(cat "$file")" 2>/dev/null; then
            echo "slurm_cluster: a cluster is running in $dir already ($file); stop it first" >&2
            exit 1
        fi
    done
    getent ahostsv4 n1 | grep -q '^127\.' ||
        fail "the node name n1 does not resolve to a loopback address: add \`127.0.0.1 n1 n2 n3\` to /etc/hosts (.ci/run does)"

    mkdir -p "$dir"/{state,spool,log,run,munge}
    dir=$(cd "$dir" && pwd)
    # munged runs as the munge user, who must reach its folder: DIR itself may be a private
    # temporary folder, so it is opened for traversal (not for reading) to everyone.
    chmod 711 "$dir"
    chown munge: "$dir/munge"
    # munged wants its socket's folder searchable by all (clients of any user connect).
    chmod 711 "$dir/munge"
    # The cluster's own key: its daemons trust no other munged, and no other trusts them.
    if [ ! -s "$dir/munge/munge.key" ]; then
        runuser -u munge -- mungekey --create --keyfile="$dir/munge/munge.key" ||
            fail "mungekey could not make a key in $dir/munge"
    fi
    runuser -u munge -- munged \
        --key-file="$dir/munge/munge.key" \
        --socket="$dir/munge/munge.socket" \
        --pid-file="$dir/munge/munged.pid" \
        --log-file="$dir/munge/munged.log" \
        --seed-file="$dir/munge/munged.seed" ||
        fail "munged did not start" "$dir/munge/munged.log"

    write_conf "$base" "$first_job" >"$dir/slurm.conf"
    export SLURM_CONF="$dir/slurm.conf"
    slurmctld -f "$SLURM_CONF" || fail "slurmctld did not start" "$dir/log/slurmctld.log"
    local node
    for node in n1 n2 n3; do
        mkdir -p "$dir/spool/$node"
        slurmd -f "$SLURM_CONF" -N "$node" || fail "slurmd -N $node did not start" "$dir/log/slurmd-$node.log"
    done

    # Ready when all three nodes are idle: until they have registered, srun would wait or fail.
    local idle=""
    for _ in $(seq 300); do
        idle=$(sinfo -h -N -t idle -o %N 2>/dev/null | sort -u | wc -l)
        [ "$idle" = 3 ] && break
        sleep 0.1
    done
    [ "$idle" = 3 ] || fail "the nodes did not come up within 30 s: $(sinfo -N 2>&1 | tr '\n' ';')" \
        "$dir/log/slurmctld.log"
    echo "SLURM_CONF=$SLURM_CONF"
}

# One controller and three nodes on loopback, with nothing that needs cgroups, systemd, a
# database or a second machine: linuxproc tracks a step's processes by their parents, task/none
# binds nothing, and accounting is off.
write_conf() {
    local base=$1 first_job=$2
    cat <<EOF
ClusterName=tessera-test
SlurmctldHost=localhost
SlurmctldPort=$base
FirstJobId=$first_job
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$dir/munge/munge.socket
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool/%n
SlurmctldPidFile=$dir/run/slurmctld.pid
SlurmdPidFile=$dir/run/slurmd-%n.pid
SlurmctldLogFile=$dir/log/slurmctld.log
SlurmdLogFile=$dir/log/slurmd-%n.log
SchedulerType=sched/builtin
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
MpiDefault=none
ReturnToService=2
SlurmdParameters=config_overrides
NodeName=n[1-3] NodeAddr=127.0.0.1 Port=$((base + 1))-$((base + 3)) CPUs=2 State=UNKNOWN
PartitionName=main Nodes=ALL Default=YES MaxTime=INFINITE State=UP
EOF
}

case $action in
start) start "${3:-}" "${4:-}" ;;
stop) stop ;;
*) usage ;;
esac
