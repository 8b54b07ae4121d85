#!/usr/bin/env bash
# Brings deploy/compose.yaml up on this machine and checks it end to end,
# through real git, real HTTP and the host's Docker engine:
#  1. secrets generated (files), images built (content-tagged, cached);
#  2. PostgreSQL, the server and 2 runners up, the scene's reference made
#     once (by one runner, as the service's reference job) and downloaded
#     by the other; a user registered (the verification link from the
#     server's file outbox), a project made;
#  3. the C++ box filter pushed twice with FBKSD_RUN: each runner does one
#     job; the first result set is published; the board read;
#  4. pushed again, and the runner holding that job stopped (docker stop)
#     mid-job: the server requeues the lost lease and the other runner
#     finishes it; the board read again, identical;
#  5. with no runner running and a job waiting, `up --scale runner=3` adds
#     a runner, which downloads the reference instead of making it and takes
#     the job (the time from the command to its first claim is printed,
#     beside the time the reference took to make); then all three run;
#  6. everything torn down (`down -v`, the runners' directories), also on
#     failure, which prints the services' last log lines first
#     (FBKSD_COMPOSE_KEEP=1 keeps the work directory with their whole logs).
# One scene at 1 and 4 spp, one repeat, a 10 s lease: a few minutes.
#
#   bash deploy/compose-check.sh [--bin-dir DIR]
#
# Without --bin-dir the release binaries are built (build-service-images.sh);
# CI passes target/debug. Prints "compose-check: passed" at the end, and
# its timings as lines "compose-check: time ...".
set -euo pipefail
caller=$(pwd)
cd "$(dirname "$0")/.."
repo_root=$(pwd)
bin_args=()
while [ $# -gt 0 ]; do
    case "$1" in
        --bin-dir) bin_args=(--bin-dir "$(cd "$caller" && cd "$2" && pwd)"); shift 2 ;;
        *) echo "usage: compose-check.sh [--bin-dir DIR]" >&2; exit 2 ;;
    esac
done
say() { echo "compose-check: $*" >&2; }
fail() { say "FAILED: $*"; exit 1; }
now_ms() { date +%s%3N; }
started_ms=$(now_ms)
seconds_since() { awk -v a="$1" -v b="$(now_ms)" 'BEGIN { printf "%.1f", (b - a) / 1000 }'; }
timing() { echo "compose-check: time $*"; }

for tool in docker docker-compose curl git python3; do
    command -v "$tool" >/dev/null || fail "$tool is missing (deploy/setup.sh installs what is needed)"
done

# --- a place of its own: work directory, project name, port ------------------------------
work=$(mktemp -d "${TMPDIR:-/tmp}/fbksd-compose-check.XXXXXX")
# Short: a run's control socket lies 76 characters below it, within a Unix socket's 107.
runtime=$(mktemp -d /dev/shm/fbc.XXXXXX 2>/dev/null || mktemp -d /tmp/fbc.XXXXXX)
project=fbksdcheck$$
port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
host=fbksd-server
url=http://$host:$port
mkdir -p "$work/runners"

# What the services are given; nothing else of the caller's FBKSD_* reaches them.
for var in $(compgen -e); do
    case "$var" in FBKSD_*) unset "$var" ;; esac
done
export FBKSD_COMPOSE_SECRETS=$work/secrets FBKSD_COMPOSE_PORT=$port FBKSD_COMPOSE_PUBLIC_HOST=$host
export FBKSD_COMPOSE_RUNNER_ROOT=$work/runners FBKSD_COMPOSE_RUNTIME_ROOT=$runtime
export FBKSD_CI_SCENES=experimental/sphere FBKSD_CI_SPP=1,4 FBKSD_CI_REPEATS=1 FBKSD_CI_POLL_SECONDS=5
export FBKSD_CI_RUN_TIMEOUT=120s FBKSD_CI_BUILD_TIMEOUT=300s
export FBKSD_SERVER_LEASE_SECONDS=10 FBKSD_SERVER_MAX_RUNS_PER_DAY=100 FBKSD_SERVER_MAX_QUEUED_JOBS_PER_USER=10
# The two runners share this machine's cores, so one calibrates while the
# other's job runs, and the drift hold (tested in the server's rules) then
# kept the stopped runner's job from the other past this check's 60 s.
export FBKSD_SERVER_HOLD_DRIFTED_RUNNERS=false
export RUST_LOG=info
dc() { docker-compose --ansi never -p "$project" -f "$repo_root/deploy/compose.yaml" --env-file "$work/images.env" "$@"; }

images_ready=""
cleanup() {
    local status=$?
    trap - EXIT INT TERM
    set +e
    if [ -n "$images_ready" ]; then
        dc logs --no-color --timestamps >"$work/services.log" 2>&1
        if [ "$status" -ne 0 ]; then
            say "the services' last lines:"
            tail -n 80 "$work/services.log" >&2
        fi
        say "tearing down"
        dc down -v --remove-orphans >/dev/null 2>&1
        # What a killed runner may have left (its own containers, by label).
        for id in $(cat "$work"/runner-ids 2>/dev/null); do
            docker ps -aq --filter "label=org.fbksd.ci.runner=$id" | xargs -r docker rm -f >/dev/null 2>&1
        done
        # The runners' files are root's: removed by a container of the runner image.
        docker run --rm --entrypoint rm -v "$work/runners:$work/runners" -v "$runtime:$runtime" \
            "$(sed -n 's/^FBKSD_IMAGE_RUNNER=//p' "$work/images.env")" -rf "$work/runners" "$runtime" >/dev/null 2>&1
    fi
    if [ "${FBKSD_COMPOSE_KEEP:-0}" = 1 ]; then
        say "kept $work"
    else
        rm -rf "$work" "$runtime"
    fi
    exit "$status"
}
trap cleanup EXIT
trap 'exit 130' INT
trap 'exit 143' TERM

# --- 1. secrets and images ------------------------------------------------------------------
# Files in a directory only this user can enter; readable inside the
# containers, whose users are not this one.
(
    umask 077
    mkdir "$work/secrets"
    cd "$work/secrets"
    random() { od -An -N16 -tx1 /dev/urandom | tr -d ' \n'; }
    password=$(random)
    printf %s "$password" >postgres_password
    printf 'postgres://fbksd:%s@postgres:5432/fbksd' "$password" >database_url
    printf 'fbksdreg_%s' "$(random)" >registration_token
    chmod 0444 ./*
)

step=$(now_ms)
bash deploy/build-service-images.sh "${bin_args[@]}" --manifest "$work/images.json" --env-file "$work/images.env" >/dev/null
images_ready=1
timing "images (built or checked): $(seconds_since "$step") s"

# --- helpers: HTTP and git to the server's public name, which is this host's loopback --------
resolve=$host:$port:127.0.0.1
auth=$work/auth-header
api() { # METHOD PATH [curl arguments]: the answer's body; fails on an HTTP error
    local method=$1 path=$2
    shift 2
    curl -sS --fail-with-body --resolve "$resolve" -X "$method" ${token:+-H @"$auth"} "$url$path" "$@"
}
json() { # EXPRESSION [ARG...]: its value on the JSON of standard input `d` (and the args `a`)
    python3 -c 'import json, sys; d = json.load(sys.stdin); a = sys.argv[2:]; v = eval(sys.argv[1])
print(v if isinstance(v, str) else json.dumps(v))' "$@"
}
push() { # push the repository's main with FBKSD_RUN; prints what the server answered
    GIT_TERMINAL_PROMPT=0 GIT_CONFIG_NOSYSTEM=1 HOME=$work GIT_CONFIG_COUNT=2 \
        GIT_CONFIG_KEY_0=http.extraHeader GIT_CONFIG_VALUE_0="Authorization: Basic $(printf 'git:%s' "$token" | base64 -w0)" \
        GIT_CONFIG_KEY_1=http.curloptResolve GIT_CONFIG_VALUE_1="$resolve" \
        git -C "$work/repo" push --porcelain -o FBKSD_RUN "$url/git/box-filter-cpp.git" main 2>&1
}
commit() {
    git -C "$work/repo" -c user.name=Check -c user.email=check@example.org commit -q --allow-empty -m "$1"
}
jobs_json() { api GET /api/v1/projects/box-filter-cpp | json 'd["jobs"]'; }
job() { api GET "/api/v1/jobs/$1"; }
# The id of the benchmark job the latest push started: the newest one not
# seen before (the ids seen are kept in a file: this runs in a subshell).
new_job() {
    local id
    touch "$work/jobs-seen"
    for _ in $(seq 100); do
        id=$(jobs_json | json "([j['id'] for j in sorted(d, key=lambda j: j['created_at'])
            if j['kind'] == 'benchmark' and j['id'] not in a] or [''])[-1]" $(cat "$work/jobs-seen"))
        if [ -n "$id" ]; then
            echo "$id" >>"$work/jobs-seen"
            echo "$id"
            return
        fi
        sleep 0.2
    done
    fail "the push started no benchmark job"
}
wait_state() { # JOB STATE SECONDS: until the job is in STATE (fails on another end)
    local deadline=$((SECONDS + $3)) state
    while :; do
        state=$(job "$1" | json 'd["state"]')
        [ "$state" = "$2" ] && return
        case "$state" in succeeded | failed | cancelled)
            api GET "/api/v1/jobs/$1/log" | json '"".join(c["text"] for c in d["chunks"])' >&2
            fail "job $1 ended $state, not $2" ;;
        esac
        [ $SECONDS -lt "$deadline" ] || fail "job $1 is still $state after $3 s"
        sleep 0.5
    done
}
# Runner containers: their ids on the server come from their logs.
runner_containers() { dc ps -q runner; }
runner_id_of() { docker logs "$1" 2>&1 | sed -n 's/.*runner [^ ]* (\([^)]*\)) ready:.*/\1/p' | tail -1; }
container_of_runner() {
    local c
    for c in $(runner_containers); do
        [ "$(runner_id_of "$c")" = "$1" ] && { echo "$c"; return; }
    done
}
wait_runners_ready() { # N SECONDS: until N running runner containers said they are ready
    local deadline=$((SECONDS + $2)) ready c id
    while :; do
        ready=0
        for c in $(docker ps -q --filter "label=com.docker.compose.project=$project" --filter "label=com.docker.compose.service=runner"); do
            id=$(runner_id_of "$c")
            if [ -n "$id" ]; then
                ready=$((ready + 1))
                grep -qx "$id" "$work/runner-ids" 2>/dev/null || echo "$id" >>"$work/runner-ids"
            fi
        done
        [ "$ready" -ge "$1" ] && return
        [ $SECONDS -lt "$deadline" ] || fail "$ready of $1 runners ready after $2 s"
        sleep 0.5
    done
}

# --- 2. up: database, server, two runners -------------------------------------------------
step=$(now_ms)
dc up -d --scale runner=2 2>&1 | sed 's/^/  /' >&2
for _ in $(seq 300); do
    api GET /readyz >/dev/null 2>&1 && break
    sleep 0.2
done
api GET /readyz >/dev/null || fail "the server is not ready at $url"
timing "up to the server ready: $(seconds_since "$step") s"
wait_runners_ready 2 300
timing "up to 2 runners ready: $(seconds_since "$step") s"
# The scene's reference: made by one runner, downloaded by the other.
made=0 downloaded=0 reference_s=
for c in $(runner_containers); do
    made=$((made + $(docker logs "$c" 2>&1 | grep -c 'references: making reference' || true)))
    downloaded=$((downloaded + $(docker logs "$c" 2>&1 | grep -c 'reference of .* downloaded' || true)))
    # From "making reference" to its job's end, by the log's own timestamps.
    reference_s=${reference_s:-$(docker logs --timestamps "$c" 2>&1 | python3 -c '
import sys, datetime
t = lambda line: datetime.datetime.fromisoformat(line.split()[0][:26])
lines = sys.stdin.read().splitlines()
start = next((t(l) for l in lines if "making reference" in l), None)
end = start and next((t(l) for l in lines if t(l) >= start and " finished" in l and "job " in l), None)
print("%.1f" % (end - start).total_seconds() if end else "")')}
done
[ "$made $downloaded" = "1 1" ] || fail "the reference was made $made times and downloaded $downloaded times (expected once each)"
timing "making the scene's reference (the reference job, on one runner): ${reference_s:-?} s"

# A user: registered, verified through the link of the mail in the file
# outbox (the server prints its links too), logged in, with an access token.
email=check@example.org
password="a long enough password"
api POST /api/v1/accounts -H 'Content-Type: application/json' \
    -d "{\"email\": \"$email\", \"password\": \"$password\"}" >/dev/null
link=""
for _ in $(seq 50); do
    link=$(dc logs --no-color server 2>/dev/null | grep -o "http://[^ ]*/accounts/verify?token=[A-Za-z0-9_-]*" | tail -1) && [ -n "$link" ] && break
    sleep 0.2
done
[ -n "$link" ] || fail "no verification link in the server's output"
dc exec -T server sh -c 'grep -l "accounts/verify" outbox/*.eml' >/dev/null || fail "the mail is not in the outbox"
curl -sS --fail --resolve "$resolve" -o /dev/null "$link"
jar=$work/cookies
csrf=$(curl -sS --fail --resolve "$resolve" -c "$jar" -b "$jar" -H 'Content-Type: application/json' \
    -d "{\"email\": \"$email\", \"password\": \"$password\"}" "$url/api/v1/sessions" | json 'd["csrf_token"]')
token=$(curl -sS --fail --resolve "$resolve" -c "$jar" -b "$jar" -H "X-CSRF-Token: $csrf" \
    -H 'Content-Type: application/json' -d '{"name": "compose-check"}' "$url/api/v1/tokens" | json 'd["token"]')
(umask 077 && printf 'Authorization: Bearer %s\n' "$token" >"$auth")
api POST /api/v1/projects -H 'Content-Type: application/json' \
    -d '{"name": "box-filter-cpp", "visibility": "private"}' >/dev/null

# The technique as a user's repository.
cp -r sdk/techniques/box-filter-cpp "$work/repo"
git -C "$work/repo" init -q -b main
git -C "$work/repo" add -A
commit "the box filter"

# --- 3. two pushes, one job for each runner; publish; the board --------------------------
step=$(now_ms)
pushed=$(push) || fail "the push failed: $pushed"
# The server answers in the push's output (a job a runner claimed before
# the answer was written shows only as "remote: FBKSD:"; new_job checks it).
grep -q "remote: FBKSD:" <<<"$pushed" || fail "the server did not answer the push: $pushed"
job1=$(new_job)
commit "again"
push >/dev/null || fail "the second push failed"
job2=$(new_job)
wait_state "$job1" succeeded 900
wait_state "$job2" succeeded 900
timing "two pushes to both results (one job per runner, in parallel): $(seconds_since "$step") s"
runner1=$(job "$job1" | json 'd["runner_id"]')
runner2=$(job "$job2" | json 'd["runner_id"]')
[ "$runner1" != "$runner2" ] || fail "one runner ($runner1) did both jobs"
say "job $job1 done by runner $runner1, job $job2 by runner $runner2"
result=$(job "$job1" | json 'd["result_id"]')
api POST "/api/v1/results/$result/publish" >/dev/null
board_before=$(api GET /api/v1/leaderboard)
grep -q box-filter-cpp <<<"$board_before" || fail "the published set is not on the board: $board_before"

# --- 4. a runner stopped mid-job; the other one finishes it --------------------------------
# This job's build waits 20 s at configure time, so the runner is stopped
# while it holds the job however slowly this script polls (the plain box
# filter's whole job took 5.9 s, and a loaded machine once let it finish
# before the stop).
echo 'execute_process(COMMAND sleep 20)  # compose-check: a build that lasts' >>"$work/repo/CMakeLists.txt"
git -C "$work/repo" add CMakeLists.txt
commit "a third time, with a slow build"
push >/dev/null || fail "the third push failed"
job3=$(new_job)
wait_state "$job3" running 120
holder=$(job "$job3" | json 'd["runner_id"]')
container=$(container_of_runner "$holder")
[ -n "$container" ] || fail "no container of runner $holder"
# Mid-job: once its log shows the build under way.
for _ in $(seq 240); do
    grep -q '\[fbksd-ci\] build: ' <<<"$(api GET "/api/v1/jobs/$job3/log")" && break
    sleep 0.25
done
step=$(now_ms)
docker stop "$container" >/dev/null
timing "docker stop of the runner holding job $job3: $(seconds_since "$step") s"
say "stopped runner $holder ($container) during job $job3"
state3=$(job "$job3" | json 'd["state"]')
[ "$state3" != succeeded ] || fail "job $job3 had already succeeded when its runner was stopped: nothing to hand out again"
# Queued again when its lease expires, then claimed at once by the other
# runner: the second attempt is what shows.
for _ in $(seq 240); do
    [ "$(job "$job3" | json 'd["attempts"]')" -ge 2 ] && break
    sleep 0.25
done
[ "$(job "$job3" | json 'd["attempts"]')" -ge 2 ] || fail "job $job3 was not handed out again within 60 s"
timing "stop to the job's second attempt (lease expired, claimed by the other runner): $(seconds_since "$step") s"
wait_state "$job3" succeeded 900
timing "stop to the job finished by the other runner: $(seconds_since "$step") s"
finisher=$(job "$job3" | json 'd["runner_id"]')
attempts=$(job "$job3" | json 'd["attempts"]')
[ "$finisher" != "$holder" ] || fail "job $job3 was finished by the stopped runner"
[ "$attempts" -ge 2 ] || fail "job $job3 took $attempts attempt(s)"
grep -q "lease expired" <<<"$(api GET "/api/v1/jobs/$job3/log")" || fail "job $job3's log does not say its lease expired"
board_after=$(api GET /api/v1/leaderboard)
[ "$board_before" = "$board_after" ] || fail "the board changed:
before: $board_before
after:  $board_after"
say "job $job3 finished by runner $finisher after $attempts attempts; the board is identical"

# --- 5. a runner added to the running service ----------------------------------------------
# A job waits with no runner running (the other one stopped too), so the
# runner added by `--scale runner=3` is the one that takes it: the time to
# its first job holds its start, registration and the references it makes.
for c in $(docker ps -q --filter "label=com.docker.compose.project=$project" --filter "label=com.docker.compose.service=runner"); do
    docker stop "$c" >/dev/null
done
commit "a fourth time"
push >/dev/null || fail "the fourth push failed"
job4=$(new_job)
before=$(runner_containers | sort)
step=$(now_ms)
dc up --no-start --scale runner=3 --no-recreate 2>&1 | sed 's/^/  /' >&2
added=$(comm -13 <(echo "$before") <(runner_containers | sort))
[ "$(echo "$added" | wc -w)" = 1 ] || fail "not one runner container added: $added"
docker start "$added" >/dev/null
wait_runners_ready 1 600
added_id=$(runner_id_of "$added")
made=$(docker logs "$added" 2>&1 | grep -c 'references: making reference' || true)
[ "$made" = 0 ] || fail "the added runner made the reference again instead of downloading it"
timing "up --scale runner=3 to the added runner ready (registered, reference downloaded): $(seconds_since "$step") s"
for _ in $(seq 240); do
    [ -n "$(job "$job4" | json 'd["started_at"] or ""')" ] && break
    sleep 0.5
done
[ "$(job "$job4" | json 'd["runner_id"] or ""')" = "$added_id" ] || fail "job $job4 was not claimed by the added runner"
claimed_after=$(job "$job4" | json "'%.1f' % ((d['started_at'] - $step) / 1000)")
timing "up --scale runner=3 to the added runner's first claimed job: $claimed_after s"
wait_state "$job4" succeeded 900
# And the others back: three runners.
dc up -d --scale runner=3 --no-recreate 2>&1 | sed 's/^/  /' >&2
wait_runners_ready 3 300
say "three runners ready; job $job4 done by the added runner $added_id"
[ "$(api GET /api/v1/leaderboard)" = "$board_before" ] || fail "the board changed with unpublished results"

timing "total: $(seconds_since "$started_ms") s"
echo "compose-check: passed"
