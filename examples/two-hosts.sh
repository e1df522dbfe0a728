#!/usr/bin/env bash
# Two hosts on one machine (docs/link.md): host A is this machine as it is (servo, sensor and
# the link board, started by `afs run`); host B is a network namespace joined to it by a veth
# pair, with a mount namespace of its own whose /dev/shm and iceoryx2 root are empty tmpfs, so
# the two hosts share no shared memory at all and talk through the link only. Host B runs the
# estimator, its own link board, and an observer that records the stack (`afs record`). The
# scenario runs; one JSON summary is printed on stdout.
#
#   examples/two-hosts.sh [--scenario surface-tracking] [--duration 30] [--seed 1]
#        [--prefix P] [--bin target/release] [--chaos KINDS [--faults N] [--cut-for S]] [--keep]
#
# As root, host A is this machine's own network. As any other user the script runs itself in a
# user namespace of its own (`unshare --user --map-root-user --net --mount`), where host A is a
# network namespace too; where the kernel refuses that, it prints {"skipped": "<why>"} and exits
# 77, the exit status of a skipped test.
#
# --chaos runs `afs chaos` on host A instead of `afs run`, with the fault kinds given
# (comma-separated, taken in turn, N faults: one of each by default), e.g. kill-link,cut-link:
# kill-link SIGKILLs host A's link board (its supervisor restarts it), cut-link takes host A's
# end of the veth pair down for --cut-for seconds (5 by default; the stack file's [chaos] table
# gets the commands).
# Everything the script makes (namespace, veth pair, processes, files) is removed at the end
# unless --keep. Nothing leaves the machine: zenoh listens and connects on the veth pair's
# addresses only, with multicast and gossip scouting off. Exit status: 0 when the run passed
# and host B's recording has no gap but where the link was cut, 1 otherwise, 2 on an error.
set -euo pipefail

scenario=surface-tracking
duration=30
seed=1
prefix="twohosts$$"
bin="$(cd "$(dirname "$0")/.." && pwd)/target/release"
chaos=""
faults=""
cut_for=5
keep=0
die() { echo "two-hosts: error: $*" >&2; exit 2; }
args=("$@")
# ip may live in an sbin folder that a user's PATH leaves out.
PATH="$PATH:/usr/sbin:/sbin"
while [ $# -gt 0 ]; do
    case "$1" in
        --scenario) scenario="$2"; shift 2 ;;
        --duration) duration="$2"; shift 2 ;;
        --seed) seed="$2"; shift 2 ;;
        --prefix) prefix="$2"; shift 2 ;;
        --bin) bin="$2"; shift 2 ;;
        --chaos) chaos="$2"; shift 2 ;;
        --faults) faults="$2"; shift 2 ;;
        --cut-for) cut_for="$2"; shift 2 ;;
        --keep) keep=1; shift ;;
        -h|--help) sed -n '2,26p' "$0"; exit 0 ;;
        *) die "unknown option '$1' (see --help)" ;;
    esac
done
# Not root: the same script again inside a user namespace, where it is root over namespaces it
# made itself; host A's network is then a namespace too.
namespace=root
if [ "$(id -u)" -ne 0 ]; then
    why=$(unshare --user --map-root-user --net --mount true 2>&1) || {
        why=${why//\"/\'}
        printf '{"skipped": "host B needs namespaces: as user %s, unshare --user --map-root-user --net --mount failed: %s"}\n' \
            "$(id -un)" "$(echo "$why" | tr '\n' ' ')"
        exit 77
    }
    exec unshare --user --map-root-user --net --mount --propagation private \
        env AFS_TWO_HOSTS_USER_NAMESPACE=1 "$0" "${args[@]}"
fi
if [ "${AFS_TWO_HOSTS_USER_NAMESPACE:-0}" = 1 ]; then
    namespace=user
    ip link set lo up
fi
bin="$(cd "$bin" 2>/dev/null && pwd)" || die "no folder of binaries at '$bin'"
for b in afs afs-servo afs-sensor afs-estimator afs-link; do
    [ -x "$bin/$b" ] || die "$bin/$b is missing: build with \`cargo build --release --workspace\`"
done
for t in ip unshare nsenter nice python3; do
    command -v "$t" >/dev/null || die "'$t' is needed"
done
if [ -z "$faults" ] && [ -n "$chaos" ]; then faults=$(echo "$chaos" | tr ',' '\n' | grep -c .); fi

work="$(mktemp -d /tmp/afs-two-hosts.XXXXXX)"
tag="$(printf '%05d' $(($$ % 100000)))"
veth_a="afsa$tag"
veth_b="afsb$tag"
# A /30 of 10.250.0.0/16 per run, from the pid.
net=$(($$ % 16384))
a_ip="10.250.$((net / 64)).$(((net % 64) * 4 + 1))"
b_ip="10.250.$((net / 64)).$(((net % 64) * 4 + 2))"
port=7447
hold=""
pids=()

cleanup() {
    set +e
    for p in "${pids[@]}"; do kill -TERM "$p" 2>/dev/null; done
    sleep 0.5
    for p in "${pids[@]}"; do kill -KILL "$p" 2>/dev/null; done
    [ -n "$hold" ] && kill -KILL "$hold" 2>/dev/null
    ip link del "$veth_a" 2>/dev/null
    if [ "$keep" -eq 0 ]; then rm -rf "$work"; else echo "two-hosts: files kept in $work" >&2; fi
}
trap cleanup EXIT
trap 'exit 2' INT TERM

# Host B: a process holding a network namespace and a mount namespace of its own, with empty
# tmpfs on /dev/shm and the iceoryx2 root. (No `ip netns`: it needs /run/netns, which a user
# namespace cannot write.)
# The iceoryx2 root is this user's (processes/ipc/mod.rs, `root_path`): afs names it.
iox_root=$("$bin/afs" iox2-config --prefix "$prefix" | sed -n 's/^root-path = "\(.*\)"$/\1/p')
[ -n "$iox_root" ] || die "afs iox2-config named no iceoryx2 root"
unshare --net --mount --propagation private sh -c \
    'mount -t tmpfs afs-b-shm /dev/shm && mkdir -p "$1" && mount -t tmpfs afs-b-iox2 "$1" && echo ready > "$0" && exec sleep 100000' \
    "$work/b.ready" "$iox_root" &
hold=$!
disown "$hold"
for _ in $(seq 100); do [ -s "$work/b.ready" ] && break; sleep 0.05; done
[ -s "$work/b.ready" ] || die "host B's namespace did not come up"
# Runs a command on host B, in place of the calling (sub)shell, so that `$!` is its pid. Host B
# stands for another machine but shares this one's CPUs: its processes run at nice 10, so that
# where SCHED_FIFO is refused (not root) host A's servo and sensor still come first, as the
# boards that are not real-time do (afs::rt::make_way_for_realtime). Not SCHED_IDLE: there
# host B's link board got the CPU only when nothing else wanted it, and with other idle work
# on the machine (the test command's lockstep tests) its batches arrived up to 1 s late and
# host B's recording lost samples (docs/link.md, *Two hosts on one machine*).
on_b() { exec nsenter -t "$hold" -m -n -- nice -n 10 "$@"; }

# The link: a veth pair, host A's end here, host B's in its namespace.
ip link add "$veth_a" type veth peer name "$veth_b" netns "$hold"
ip addr add "$a_ip/30" dev "$veth_a"
ip link set "$veth_a" up
nsenter -t "$hold" -n ip addr add "$b_ip/30" dev "$veth_b"
nsenter -t "$hold" -n ip link set "$veth_b" up
nsenter -t "$hold" -n ip link set lo up

# Host B's boards and observer.
# (Stopped in this order at the end: the link board last, as it leaves the prefix clean.)
on_b "$bin/afs-estimator" --prefix "$prefix" --scenario "$scenario" --seed "$seed" \
    2>"$work/b-estimator.log" &
pids+=($!)
on_b "$bin/afs-link" --prefix "$prefix" --side remote --listen "tcp/$b_ip:$port" \
    --connect "tcp/$a_ip:$port" --summary "$work/b-link.json" 2>"$work/b-link.log" &
pids+=($!)
sleep 0.3
on_b "$bin/afs" record --prefix "$prefix" --out "$work/b.mcap" --json \
    >"$work/b-record.json" 2>"$work/b-record.log" &
record_pid=$!
pids+=("$record_pid")
# An operator's look at the stack from host B, half-way through the run: `afs status`, then
# the Python client of the servo's stream (5 000 ticks).
python_client="$(cd "$(dirname "$0")" && pwd)/python/servo_subscriber.py"
( sleep "$(python3 -c "print(float('$duration') / 2)")"
  ( on_b "$bin/afs" status --prefix "$prefix" --json >"$work/b-status.json" 2>"$work/b-status.log" ) || true
  on_b python3 "$python_client" --prefix "$prefix" --count 5000 --timeout 5 --json \
      >"$work/b-python.json" 2>"$work/b-python.log" ) &
status_pid=$!

# Host A: the stack file with the link board on host A's address.
sed "s#tcp/127.0.0.1:7447#tcp/$a_ip:$port#" "$(dirname "$0")/stack-two-hosts.toml" >"$work/host-a.toml"
run=(run)
if [ -n "$chaos" ]; then
    # How afs chaos cuts this link: host A's end of the veth pair down, and up again.
    cat >>"$work/host-a.toml" <<TOML

[chaos]
cut_link = ["ip", "link", "set", "$veth_a", "down"]
restore_link = ["ip", "link", "set", "$veth_a", "up"]
cut_for_s = $cut_for
TOML
    run=(chaos --faults "$chaos" --kills "$faults" --in-turn)
fi
set +e
"$bin/afs" "${run[@]}" --config "$work/host-a.toml" --prefix "$prefix" --scenario "$scenario" \
    --duration "$duration" --seed "$seed" --json >"$work/a-run.json" 2>"$work/a-run.log"
run_status=$?
set -e

wait "$status_pid" 2>/dev/null || true
# Host B's observer leaves when host A's supervisor says it stops; then its boards.
for _ in $(seq 200); do kill -0 "$record_pid" 2>/dev/null || break; sleep 0.05; done
for p in "${pids[@]}"; do
    kill -TERM "$p" 2>/dev/null || true
    for _ in $(seq 100); do kill -0 "$p" 2>/dev/null || break; sleep 0.05; done
    if kill -0 "$p" 2>/dev/null; then
        echo "two-hosts: warning: pid $p did not stop on SIGTERM within 5 s, killed" >&2
        kill -KILL "$p" 2>/dev/null || true
    fi
    wait "$p" 2>/dev/null || true
done
pids=()
# What the stack's processes left on host B (nothing, when they stop cleanly).
leftover=$(on_b sh -c 'find /dev/shm "$0" -name "afs_*" 2>/dev/null | tr "\n" " "' "$iox_root" || true)

python3 - "$work" "$run_status" "$leftover" "$chaos" "$cut_for" "$namespace" <<'EOF'
import json, sys, os
work, run_status, leftover, chaos, cut_for, namespace = sys.argv[1:7]
def load(name):
    try:
        with open(os.path.join(work, name)) as f:
            return json.load(f)
    except Exception as e:
        return {"error": f"{name}: {e}"}
a, rec, link = load("a-run.json"), load("b-record.json"), load("b-link.json")
status, python = load("b-status.json"), load("b-python.json")
def warnings(name):
    """The warnings and errors in a board's log (iceoryx2's `[W]`/`[E]` entries, afs's own
    lines): how many, and the first few, so that a failed run says what the board saw."""
    try:
        with open(os.path.join(work, name), errors="replace") as f:
            lines = [l.strip() for l in f]
    except OSError as e:
        return {"count": None, "first": [f"{name}: {e}"]}
    hits = []
    for i, l in enumerate(lines):
        if l.startswith("afs-link: {"):
            continue  # the summary
        if "[W]" in l or "[E]" in l or "[F]" in l or "warning" in l or "error" in l:
            # iceoryx2 puts the message on the line after its origin.
            nxt = lines[i + 1] if i + 1 < len(lines) and lines[i + 1].startswith("|") else ""
            hits.append((l + " " + nxt).strip()[:300])
    return {"count": len(hits), "first": hits[:5]}
procs = {p.get("name"): p for p in a.get("processes", [])} if "processes" in a else {}
servo = rec.get("servo", {})
faults = (a.get("chaos") or {}).get("faults", [])
out = {
    "passed": False,
    # "root": host A is this machine's network; "user": the run was in a user namespace.
    "namespace": namespace,
    "run": {
        "exit_status": int(run_status),
        "passed": a.get("passed"),
        "scenario": a.get("scenario"),
        "failed_checks": [c.get("id") for c in a.get("checks", []) if not c.get("pass")],
        "estimates": a.get("stack", {}).get("tracking", {}).get("estimations", {}).get("estimates"),
        "agreement": a.get("agreement"),
        "link_board_restarts": procs.get("link", {}).get("restarts"),
    },
    "host_b": {
        "recording": rec.get("recording"),
        "ended": rec.get("ended"),
        "servo_samples": servo.get("received"),
        "servo_missing": servo.get("missing"),
        "servo_gaps": servo.get("first_gaps"),
        "link": link,
        "link_warnings": warnings("b-link.log"),
        "leftover_files": leftover.split(),
        # `afs status` on host B: host A's processes as its supervisor reports them, and the
        # servo loop's statistics, both mirrored by the link.
        "status": {
            "error": status.get("error"),
            "processes": {p.get("name"): p.get("state") for p in (status.get("processes") or [])},
            "loop_stats": status.get("loop") is not None,
            "scenario": (status.get("supervisor") or {}).get("scenario"),
        },
        # The Python client of the servo's stream on host B (examples/python).
        "python": python,
    },
    "chaos": {
        "faults": [{k: f.get(k) for k in ("kind", "injected_at_s", "back_ms", "note")} for f in faults],
    } if chaos else None,
}
estimates = out["run"]["estimates"] or 0
failed = out["run"]["failed_checks"]
period_s = (a.get("loop") or {}).get("period_us", 100.0) * 1e-6
out["run"]["estimator_link"] = (a.get("loop") or {}).get("estimator")
if chaos:
    # Host A must stay safe and keep its own data; only the agreement with the lockstep may
    # go (a request that a cut outlasted is given up, as with a dead estimator). A killed link
    # board is restarted by the supervisor, and host B sees a new packer (epoch). Every gap of
    # host B's recording must be reported and lie where a fault was (servo ticks, from 2 s
    # before the injection to 8 s after the link is back: zenoh's reconnection, with margin;
    # a cut within zenoh's 10-s lease is left to TCP, whose backoff can hold the data as long
    # again after the cut's end).
    kills = sum(1 for f in faults if f.get("kind") == "kill-link")
    windows = []
    for f in faults:
        t = f.get("injected_at_s") or 0.0
        cut = float(cut_for) if f.get("kind") == "cut-link" else 0.0
        back = cut + (cut if cut <= 10.0 else 0.0)
        windows.append(((t - 2.0) / period_s, (t + back + 8.0) / period_s))
    gaps = servo.get("first_gaps", [])
    inside = lambda g: any(lo <= g["first"] and g["first"] + g["missing"] <= hi for lo, hi in windows)
    out["chaos"]["gaps"] = len(gaps)
    out["chaos"]["gaps_inside"] = all(inside(g) for g in gaps)
    out["chaos"]["link_epochs"] = (link.get("unpacked") or {}).get("epochs")
    ok_run = set(failed) <= {"lockstep_agreement"} \
        and len(faults) == int((a.get("chaos") or {}).get("planned", -1)) \
        and procs.get("link", {}).get("restarts") == kills
    ok_gaps = out["chaos"]["gaps_inside"] and servo.get("gaps", 0) == len(gaps) \
        and out["chaos"]["link_epochs"] == 1 + kills
else:
    ok_run = int(run_status) == 0 and bool(a.get("passed")) and estimates >= 1 \
        and bool((a.get("agreement") or {}).get("agrees"))
    ok_gaps = servo.get("missing", 1) == 0
out["passed"] = bool(ok_run and ok_gaps and "error" not in a and (servo.get("received") or 0) > 0
                     and servo.get("last") == (a.get("stack") or {}).get("ticks")
                     and not leftover.split() and rec.get("ended") == "stopping")
print(json.dumps(out, indent=2))
sys.exit(0 if out["passed"] else 1)
EOF
