#!/usr/bin/env bash
# A cluster on one machine: N "hosts" that are Linux network namespaces, each with one veth
# link to a bridge (itself in a namespace of its own, so the root namespace is never touched),
# addresses in a private test subnet, optional per-link rate caps (tc tbf), and an rsh agent
# with which mpirun, started on host 0, launches its daemons on the other hosts.
#
#   testbed.sh up N [--rate R] [--slots S] [--tcp-retries T]
#                                            create hosts ID-h0 .. ID-h(N-1) (removes leftovers first)
#   testbed.sh run CMD...                    run CMD on host 0 (where mpirun starts)
#   testbed.sh on K CMD...                   run CMD on host K
#   testbed.sh mpirun ARGS...                mpirun on host 0 across the hosts (TCP only)
#   testbed.sh link K down|up                pull / plug host K's cable (the switch side)
#   testbed.sh counters                      "K IF TX_BYTES RX_BYTES" per host (kernel counters)
#   testbed.sh env                           ICR_* variables describing the test bed
#   testbed.sh down                          remove everything (processes, links, namespaces, state)
#   testbed.sh with N [up options] -- CMD...
#                                            up, run CMD (in the root namespace, with the ICR_*
#                                            variables set), and always down, also when CMD fails
#                                            or this script is interrupted or terminated
#   testbed.sh sweep                         remove instances whose owning process is gone
#
# Environment: ICR_TESTBED_ID (name prefix, default "icr"; letters, digits and '-', since
# OpenMPI refuses host names with '_'), ICR_TESTBED_NET (first three octets of the /24 test
# subnet, default 10.231.0), ICR_TESTBED_OWNER (pid whose death makes the instance stale for
# `sweep`; default: the caller). Only addresses in the test subnet, on the private bridge, are
# ever used: nothing leaves these namespaces.
#
# Exit code 77 (and one line "testbed: SKIPPED: reason" on stderr) when the test bed cannot
# run here: not root, no `ip`, or network namespaces not allowed.

set -u
set -o pipefail

SKIP=77
ID=${ICR_TESTBED_ID:-icr}
NET=${ICR_TESTBED_NET:-10.231.0}
SELF=$(readlink -f "$0" 2>/dev/null || echo "$0")
if [ -w /run ]; then STATE_ROOT=/run/icrender-testbed; else STATE_ROOT=${TMPDIR:-/tmp}/icrender-testbed; fi
STATE=$STATE_ROOT/$ID
BR=$ID-br

die() {
    echo "testbed: error: $*" >&2
    exit 1
}

skip() {
    echo "testbed: SKIPPED: $*" >&2
    exit $SKIP
}

check_id() {
    [[ $ID =~ ^[a-z][a-z0-9-]{0,19}$ ]] || die "ICR_TESTBED_ID '$ID': use lower-case letters, digits and '-' (at most 20)"
    [[ $NET =~ ^[0-9]{1,3}\.[0-9]{1,3}\.[0-9]{1,3}$ ]] || die "ICR_TESTBED_NET '$NET': three octets, e.g. 10.231.0"
}

require() {
    command -v ip >/dev/null 2>&1 || skip "no 'ip' command (iproute2)"
    [ "$(id -u)" = 0 ] || skip "needs root (network namespaces, veth links, tc)"
}

host() { echo "$ID-h$1"; }

# The number of hosts of the running instance (0 when there is none).
host_count() {
    [ -f "$STATE/hosts" ] && wc -l <"$STATE/hosts" || echo 0
}

lock() {
    mkdir -p "$STATE_ROOT"
    exec 9>"$STATE_ROOT/lock"
    command -v flock >/dev/null 2>&1 && flock 9
}

unlock() {
    exec 9>&-
}

# Namespaces belonging to an instance id: its hosts and its bridge.
namespaces_of() {
    ip netns list 2>/dev/null | awk '{print $1}' | grep -E "^$1-(h[0-9]+|br)\$"
}

# Ends the processes inside a namespace (only ours: the namespace is this test bed's), then
# deletes it. A namespace whose name is gone but which a process still holds would keep its
# links alive unseen, hence the processes first.
remove_namespace() {
    local ns=$1 pids tries
    for sig in TERM KILL; do
        pids=$(ip netns pids "$ns" 2>/dev/null | tr '\n' ' ')
        [ -n "${pids// /}" ] || break
        # shellcheck disable=SC2086
        kill -$sig $pids 2>/dev/null
        for tries in 1 2 3 4 5 6 7 8 9 10; do
            pids=$(ip netns pids "$ns" 2>/dev/null | tr '\n' ' ')
            [ -n "${pids// /}" ] || break
            sleep 0.1
        done
    done
    ip netns delete "$ns" 2>/dev/null
}

teardown() {
    local id=$1 ns
    # Hosts first (their processes), the bridge last.
    for ns in $(namespaces_of "$id" | sort -r); do
        remove_namespace "$ns"
    done
    rm -rf "${STATE_ROOT:?}/$id"
    ! namespaces_of "$id" >/dev/null
}

# Instances of this script whose owner has gone (a crashed or killed test run).
sweep() {
    local ns id owner
    for ns in $(ip netns list 2>/dev/null | awk '{print $1}' | grep -E '^icr[a-z0-9-]*-br$'); do
        id=${ns%-br}
        [ "$id" = "$ID" ] && continue
        owner=$(cat "$STATE_ROOT/$id/owner" 2>/dev/null)
        if [ -n "$owner" ] && kill -0 "$owner" 2>/dev/null; then
            continue
        fi
        teardown "$id"
    done
}

up() {
    local n=$1 rate="" slots=1 retries=5 k h ip burst
    shift
    while [ $# -gt 0 ]; do
        case $1 in
            --rate) rate=${2:?--rate needs a value}; shift 2 ;;
            --slots) slots=${2:?--slots needs a value}; shift 2 ;;
            --tcp-retries) retries=${2:?--tcp-retries needs a value}; shift 2 ;;
            *) die "up: unknown option $1" ;;
        esac
    done
    [[ $n =~ ^[0-9]+$ ]] && [ "$n" -ge 1 ] && [ "$n" -le 200 ] || die "up: N must be 1..200"
    [[ $slots =~ ^[0-9]+$ ]] && [ "$slots" -ge 1 ] || die "up: --slots must be a positive number"
    [[ $retries =~ ^[0-9]+$ ]] && [ "$retries" -ge 1 ] && [ "$retries" -le 15 ] || die "up: --tcp-retries must be 1..15"
    if [ -n "$rate" ]; then
        command -v tc >/dev/null 2>&1 || skip "no 'tc' command (iproute2) for --rate"
        burst=$(burst_for "$rate") || die "up: --rate '$rate': use e.g. 1gbit, 100mbit, 500kbit"
    fi
    lock
    sweep
    teardown "$ID" || die "could not remove the leftovers of '$ID'"
    local err
    err=$(ip netns add "$BR" 2>&1) || skip "cannot create network namespaces: ${err//$'\n'/ }"
    mkdir -p "$STATE"
    echo "${ICR_TESTBED_OWNER:-$PPID}" >"$STATE/owner"
    # No IPv6 anywhere: its autoconfiguration chatter would add to the counted bytes.
    step ipv6_off "$BR"
    step ip -n "$BR" link set lo up
    step ip -n "$BR" link add br0 type bridge
    step ip -n "$BR" link set br0 up
    : >"$STATE/hosts"
    for ((k = 0; k < n; k++)); do
        h=$(host $k)
        ip="$NET.$((k + 1))"
        step ip netns add "$h"
        step ipv6_off "$h"
        step ip -n "$h" link set lo up
        # How long TCP keeps retransmitting to a peer that has vanished: Linux's default (15)
        # is about 15 minutes, during which an mpirun that must abort a job cannot reach the
        # lost host's daemon and waits. 5 gives up after about 15 s.
        step ip netns exec "$h" sh -c "echo $retries >/proc/sys/net/ipv4/tcp_retries2"
        step ip -n "$BR" link add "h$k" type veth peer name eth0 netns "$h"
        step ip -n "$BR" link set "h$k" master br0
        step ip -n "$BR" link set "h$k" up
        step ip -n "$h" addr add "$ip/24" dev eth0
        step ip -n "$h" link set eth0 up
        if [ -n "$rate" ]; then
            # Both directions of the link: the host's sending (eth0) and its receiving (the
            # bridge port's sending).
            step tc -n "$h" qdisc replace dev eth0 root tbf rate "$rate" burst "$burst" latency 50ms
            step tc -n "$BR" qdisc replace dev "h$k" root tbf rate "$rate" burst "$burst" latency 50ms
        fi
        echo "$k $h $ip" >>"$STATE/hosts"
    done
    write_files "$n" "$slots" "$rate"
    unlock
}

# A step of `up`: on failure, nothing is left half made.
step() {
    local err
    err=$("$@" 2>&1) && return 0
    echo "testbed: error: $* failed: ${err//$'\n'/ }" >&2
    teardown "$ID"
    exit 1
}

ipv6_off() {
    ip netns exec "$1" sh -c 'for f in /proc/sys/net/ipv6/conf/all/disable_ipv6 /proc/sys/net/ipv6/conf/default/disable_ipv6; do [ -w "$f" ] && echo 1 >"$f"; done; true'
}

# A token bucket of 10 ms at the rate (at least 32 KiB): enough for the timer's granularity.
burst_for() {
    local r=${1,,} num unit bps
    [[ $r =~ ^([0-9]+)([kmg]?)(bit|bps)$ ]] || return 1
    num=${BASH_REMATCH[1]}
    unit=${BASH_REMATCH[2]}
    case $unit in k) bps=$((num * 1000)) ;; m) bps=$((num * 1000000)) ;; g) bps=$((num * 1000000000)) ;; *) bps=$num ;; esac
    [ "${BASH_REMATCH[3]}" = bps ] && bps=$((bps * 8))
    local bytes=$((bps / 8 / 100))
    [ $bytes -lt 32768 ] && bytes=32768
    echo "$bytes"
}

write_files() {
    local n=$1 slots=$2 rate=$3 k
    : >"$STATE/hostfile"
    for ((k = 0; k < n; k++)); do
        echo "$(host $k) slots=$slots" >>"$STATE/hostfile"
    done
    # OpenMPI's rsh launcher calls: AGENT [options] HOST COMMAND, the command as one string.
    # The host gets its own UTS namespace so that it also calls itself by its name.
    cat >"$STATE/rsh-agent" <<'EOF'
#!/bin/sh
while [ $# -gt 0 ]; do case $1 in -*) shift ;; *) break ;; esac; done
host=$1
shift
exec ip netns exec "$host" unshare --uts sh -c 'hostname "$0" && eval "$1"' "$host" "$*"
EOF
    cat >"$STATE/mpirun" <<EOF
#!/bin/sh
# mpirun across the test bed's hosts: TCP only, on the test subnet only.
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
exec mpirun --hostfile $STATE/hostfile \\
    --mca plm_rsh_agent $STATE/rsh-agent --mca plm_rsh_no_tree_spawn 1 \\
    --mca pml ob1 --mca btl tcp,self \\
    --mca btl_tcp_if_include $NET.0/24 --mca oob_tcp_if_include $NET.0/24 \\
    "\$@"
EOF
    chmod +x "$STATE/rsh-agent" "$STATE/mpirun"
    cat >"$STATE/env" <<EOF
ICR_TESTBED_ID=$ID
ICR_TESTBED_STATE=$STATE
ICR_TESTBED_HOSTS=$n
ICR_TESTBED_SUBNET=$NET.0/24
ICR_TESTBED_RATE=$rate
ICR_HOSTFILE=$STATE/hostfile
ICR_RSH_AGENT=$STATE/rsh-agent
ICR_MPIRUN=$STATE/mpirun
ICR_TESTBED=$SELF
EOF
}

need_up() {
    [ -f "$STATE/hosts" ] && ip netns list 2>/dev/null | awk '{print $1}' | grep -qx "$(host 0)" ||
        die "no test bed '$ID' is up (testbed.sh up N)"
}

# Runs a command on host K, which also calls itself by its host name (for mpirun).
on_host() {
    local k=$1
    shift
    [ $# -gt 0 ] || die "no command"
    need_up
    local h
    h=$(host "$k")
    ip netns list | awk '{print $1}' | grep -qx "$h" || die "no host $k"
    set -a
    # shellcheck disable=SC1091
    . "$STATE/env"
    set +a
    exec ip netns exec "$h" unshare --uts sh -c 'hostname "$0" && exec "$@"' "$h" "$@"
}

link() {
    local k=${1:?link K down|up} state=${2:?link K down|up}
    [ "$state" = up ] || [ "$state" = down ] || die "link: up or down"
    need_up
    ip -n "$BR" link set "h$k" "$state" || die "no link to host $k"
}

counters() {
    need_up
    local k h ip
    while read -r k h ip; do
        echo "$k eth0 $(ip netns exec "$h" cat /sys/class/net/eth0/statistics/tx_bytes /sys/class/net/eth0/statistics/rx_bytes | tr '\n' ' ')"
    done <"$STATE/hosts"
}

with() {
    local args=() n
    n=${1:?with N [--rate R] -- CMD...}
    shift
    while [ $# -gt 0 ] && [ "$1" != -- ]; do
        args+=("$1")
        shift
    done
    [ "${1:-}" = -- ] || die "with: missing -- before the command"
    shift
    [ $# -gt 0 ] || die "with: no command"
    export ICR_TESTBED_OWNER=$$
    child=""
    cleanup() {
        trap - EXIT INT TERM HUP
        [ -n "$child" ] && kill -TERM "$child" 2>/dev/null
        lock
        teardown "$ID"
        unlock
    }
    trap 'cleanup' EXIT
    trap 'cleanup; exit 130' INT
    trap 'cleanup; exit 143' TERM
    trap 'cleanup; exit 129' HUP
    (up "$n" "${args[@]}") || exit $?
    set -a
    # shellcheck disable=SC1091
    . "$STATE/env"
    set +a
    # In the background, so that a signal reaches the trap at once rather than after CMD.
    "$@" <&0 &
    child=$!
    wait "$child"
    local rc=$?
    child=""
    exit $rc
}

main() {
    check_id
    local cmd=${1:-}
    [ $# -gt 0 ] && shift
    case $cmd in
        up) require; up "${1:?up N}" "${@:2}" ;;
        down) require; lock; teardown "$ID" || die "could not remove everything of '$ID'"; unlock ;;
        sweep) require; lock; sweep; unlock ;;
        run) require; on_host 0 "$@" ;;
        on) require; on_host "${1:?on K CMD...}" "${@:2}" ;;
        mpirun) require; need_up; on_host 0 "$STATE/mpirun" "$@" ;;
        link) require; link "$@" ;;
        counters) require; counters ;;
        env) need_up; cat "$STATE/env" ;;
        with) require; with "$@" ;;
        *) sed -n '2,/^$/s/^# \{0,1\}//p' "$SELF" >&2; exit 2 ;;
    esac
}

main "$@"
