#!/usr/bin/env bash
# Equal time against noise, at full size: the check of
# tests/tests/results.rs (equal_time_ties_copies_and_ranks_doubled_work_below)
# repeated as issue 48 asks. Each repetition is one `fbksd run --repeats 3`
# of three techniques on the experimental sphere and sin-bands at 4 and
# 16 spp, then `fbksd results compute`:
#   a, b      the same program under two names (a box filter doing ROUNDS
#             rounds of arithmetic per sample, default 30: about as much
#             work as rendering the sample)
#   doubled   the same program with a busy loop that doubles its work
# and prints, per repetition, the mean ranks at equal samples and at equal
# time, then how many repetitions tied the copies at both and ranked the
# doubled one below them at equal time. Release binaries (FBKSD_PROFILE=debug:
# those of `cargo build --workspace`, as they are); run it on an otherwise
# idle machine. MAX_REPEATS=M adds `--max-repeats M --metrics MSE` (more
# seeds where they decide) and reports the runs that got more seeds.
#
#   [ROUNDS=N] [MAX_REPEATS=M] [FBKSD_PROFILE=debug] bash deploy/bench-equal-time.sh [REPETITIONS]   # default 20
set -euo pipefail
cd "$(dirname "$0")/.."
repetitions=${1:-20}
rounds=${ROUNDS:-30}
more=()
[ -n "${MAX_REPEATS:-}" ] && more=(--max-repeats "$MAX_REPEATS" --metrics MSE)
work=$PWD/target/bench-equal-time
rm -rf "$work" && mkdir -p "$work"
case "${FBKSD_PROFILE:-release}" in
    release)
        cargo build --release --locked -p fbksd -p fbksd-procedural -p fbksd-tests \
            --bin fbksd --bin fbksd-procedural --bin fbksd-test-technique >&2
        bin=$PWD/target/release ;;
    debug) bin=$PWD/target/debug ;;
    *) echo "bench-equal-time: FBKSD_PROFILE must be release or debug, not '$FBKSD_PROFILE'" >&2; exit 1 ;;
esac
export PATH="$bin:$PATH"
scenes=(scenes/experimental/sphere scenes/experimental/sin-bands)
for scene in "${scenes[@]}"; do
    fbksd-procedural reference "$scene" >&2
done
technique="$bin/fbksd-test-technique"

echo "CPU: $(sed -n 's/^model name\s*: //p' /proc/cpuinfo | head -1), $(nproc) cores; ${repetitions} repetitions, ${rounds} rounds per sample${MAX_REPEATS:+, at most $MAX_REPEATS seeds per run}"
echo
echo "| repetition | a, b, doubled at equal spp | a, b, doubled at equal time | copies tie at both | doubled below at equal time | runs with more seeds | wall s |"
echo "|---|---|---|---|---|---|---|"
for i in $(seq 1 "$repetitions"); do
    results=$work/results-$i
    started=$EPOCHREALTIME
    fbksd run "${more[@]}" -t "a=$technique box-filter $rounds" -t "b=$technique box-filter $rounds" \
        -t "doubled=$technique box-filter-doubled $rounds" \
        -s "${scenes[0]}" -s "${scenes[1]}" --spp 4,16 --repeats 3 --results "$results" >"$work/run-$i.log" 2>&1 &&
        fbksd results compute --results "$results" --scenes scenes --metrics MSE >>"$work/run-$i.log" 2>&1 ||
        { cat "$work/run-$i.log" >&2; exit 1; }
    python3 - "$results/index.json" "$i" "$started" "$EPOCHREALTIME" <<'PY'
import json, sys
index, i, wall = json.load(open(sys.argv[1])), sys.argv[2], float(sys.argv[4]) - float(sys.argv[3])
def ranks(kind):
    return {s["technique"]: s["mean_rank"] for s in index["rankings"][kind]["standings"]}
spp, time = ranks("equal_spp"), ranks("equal_time")
tie = spp["a"] == spp["b"] and time["a"] == time["b"]
below = time["doubled"] > max(time["a"], time["b"])
show = lambda r: " / ".join(f"{r[t]:.2f}" for t in ("a", "b", "doubled"))
more = [f"{r['technique']} {r['scene']} {r['spp']}: {len(r['repeats'])}" for r in index["runs"] if len(r["repeats"]) > 3]
print(f"| {i} | {show(spp)} | {show(time)} | {'yes' if tie else 'NO'} | {'yes' if below else 'NO'} | {', '.join(more) or 'none'} | {wall:.1f} |")
PY
done | tee "$work/table.md"
echo
awk -F'|' -v n="$repetitions" '$5 ~ /yes/ { tie++ } $6 ~ /yes/ { below++ } $7 !~ /none/ { more++ } { wall += $8 }
    END { printf "copies tied at equal spp and at equal time in %d of %d; doubled ranked below them at equal time in %d of %d; more seeds in %d of %d; %.1f s per repetition\n", tie, n, below, n, more, n, wall / n }' "$work/table.md"
