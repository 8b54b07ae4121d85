#!/usr/bin/env bash
# Timing noise: the C++ and the Python box filter, NFOR (C++, OpenMP) and
# NL-means (Python) on the procedural sphere and the Embree Cornell box at
# 16 spp, each run REPEATS times (default 5) with other sample seeds through
# `fbksd run` with release binaries; prints, per technique and scene, the
# median cost (the equal-time axis, sdk/exchange/src/cost.rs, as `fbksd
# results compute` records it in the index), the
# technique's CPU time after its hello, its start-up, and the wall times
# of before (technique time, time to result), each with its coefficient of
# variation over the seeds (markdown, on stdout). The C++ techniques are
# built as the service builds them (deploy/bench-env.sh).
#
#   [REPEATS=N] bash deploy/bench-timing.sh
set -euo pipefail
cd "$(dirname "$0")/.."
work=$PWD/target/bench-timing
source deploy/bench-env.sh
bench_env "$work"
target/release/fbksd-procedural reference scenes/experimental/sphere >&2
target/release/fbksd-embree reference scenes/production-small/cornell-box >&2
box=$(build_technique box-filter-cpp)
nfor=$(build_technique nfor)
target/release/fbksd run -t "box-filter-cpp=$box/box-filter-cpp" -t "nfor=$nfor/nfor" \
    -t "nlm=sdk/techniques/nlm/nlm.py" -t "box-filter-python=sdk/techniques/box-filter-python/box_filter.py" -s scenes/experimental/sphere -s scenes/production-small/cornell-box \
    --spp 16 --repeats "${REPEATS:-5}" --results "$work/results" >&2
# The metrics' ranking records each run's cost by seed, as equal time charges it.
target/release/fbksd results compute --results "$work/results" --scenes scenes --metrics MSE >&2
python3 - "$work/results/index.json" <<'PY'
import json, statistics as st, sys
index = json.load(open(sys.argv[1]))
costs = {(c["technique"], c["scene"], c["spp"]): c["by_seed"] for c in index["rankings"]["costs"]}
def summary(values):
    m = st.mean(values)
    return f"{st.median(values):.1f} ms | {100 * st.stdev(values) / m:.1f} %" if len(values) > 1 and m > 0 else "– | –"
print("| technique | scene | seeds | cost | CV | technique CPU | CV | start-up | CV | technique time (wall) | CV | time to result (wall) | CV |")
print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
for r in sorted(index["runs"], key=lambda r: (r["technique"], r["scene"])):
    ok = [p for p in r["repeats"] if p["status"] == "ok"]
    cost = list(costs[(r["technique"], r["scene"], r["spp"])].values())
    column = lambda f: summary([f(p) for p in ok])
    print(f"| {r['technique']} | {r['scene']} | {len(ok)} | {summary(cost)} | {column(lambda p: p['technique_cpu_ms'])} | "
          f"{column(lambda p: p['startup_ms'])} | {column(lambda p: p['technique_ms'])} | "
          f"{column(lambda p: p['technique_ms'] + p['waiting_ms'])} |")
PY
