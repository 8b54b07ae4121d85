#!/usr/bin/env python3
"""How far a job moves a technique's own CPU time beyond what its seeds
explain, read off the sets deploy/bench-service-ties.sh keeps: the figure
behind the equal-time rule's job noise (fbksd_exchange::stats::JOB_NOISE,
in units of the seed-to-seed noise).

    python3 deploy/job-noise.py [--job-noise K] [--seeds N] WORK_DIR...

Every published set of a group's copies (techniques/groups.txt: a group's
name, then its two copies; every season benchmarks each copy in a job of its
own) is one job of that program. Only the seeds its benchmark job measured count
(--seeds, default 3: seeds 0 to N-1): seeds jobs add more seeds to a set
from a job of their own. Per program and scene, over its jobs and
budgets, it prints:

  seed sd     the pooled sd of the log own CPU time from seed to seed
              inside a job (about its CV), and its degrees of freedom;
  job sd      the sd a job adds to a run's mean log time, from the
              scatter of the jobs' means at each budget beyond the
              seeds' share (sd²/n), pooled over the budgets; also as a
              multiple of the seed sd (the estimate of JOB_NOISE);
  pairs       every two jobs at one budget: how many, the farthest apart
              (|difference of mean log times| in seed sds), and how many lie
              beyond the rule's 1 % threshold t₀.₉₉₅·√(2/n + 2K²) at K =
              --job-noise (default 1.5, the rule's);
  K for none  the job noise at which no pair would lie beyond.

The rule pools its seed noise over every technique at a scene and scales it
to a point's share of the cost; both cancel in a pair of one program's jobs
(the same share, and each program's own noise is what scatters), so the
figures here are in each program's own seed sd."""
import argparse
import glob
import itertools
import json
import math
import statistics
from collections import defaultdict


def t_quantile(p, df):
    """Student's t quantile (Cornish-Fisher expansion about the normal's;
    within 1e-3 of the exact value from df 10 on)."""
    z = statistics.NormalDist().inv_cdf(p)
    g1 = (z**3 + z) / 4
    g2 = (5 * z**5 + 16 * z**3 + 3 * z) / 96
    g3 = (3 * z**7 + 19 * z**5 + 17 * z**3 - 15 * z) / 384
    return z + g1 / df + g2 / df**2 + g3 / df**3


def jobs_of(work):
    """{program: [set]} for one work directory: the sets of each group's copies."""
    groups = [line.split() for line in open(f"{work}/techniques/groups.txt")]
    program = {name: label for label, *copies in groups for name in copies[:2]}
    # A board lists each set once per group of scenes.
    sets = {(entry["technique"], entry["result_id"])
            for board in glob.glob(f"{work}/board-*.json")
            for group in json.load(open(board))["groups"] for entry in group["entries"]}
    found = defaultdict(list)
    for technique, set_id in sorted(sets):
        if technique in program:
            found[program[technique]].append(json.load(open(f"{work}/sets/{set_id}.json")))
    return found


def own_logs(result, seeds):
    """{(scene, spp): [log own CPU ms by seed]} of one set's first `seeds` seeds."""
    cells = {}
    for run in result["runs"]:
        logs = [math.log(r["technique_cpu_ms"]) for r in run["repeats"]
                if r["seed"] < seeds and r["status"] == "ok" and r["technique_cpu_ms"] > 0]
        if len(logs) >= 2:
            cells[(run["scene"], run["spp"])] = logs
    return cells


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--job-noise", type=float, default=1.5)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("work", nargs="+")
    args = parser.parse_args()
    programs = defaultdict(list)
    for work in args.work:
        for program, sets in jobs_of(work).items():
            programs[program] += [own_logs(s, args.seeds) for s in sets]
    print(f"| program | scene | jobs | seed sd (df) | job sd | job sd / seed sd | pairs | farthest (seed sds) | beyond at K={args.job_noise} | K for none |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for program, jobs in sorted(programs.items()):
        for scene in sorted({scene for job in jobs for scene, _ in job}):
            budgets = sorted({spp for job in jobs for s, spp in job if s == scene})
            # Seeds: the residuals about each job's mean at each budget.
            squares = df = 0
            for job in jobs:
                for spp in budgets:
                    logs = job.get((scene, spp), [])
                    if len(logs) >= 2:
                        mean = statistics.fmean(logs)
                        squares += sum((x - mean) ** 2 for x in logs)
                        df += len(logs) - 1
            if df == 0:
                continue
            seed_sd = math.sqrt(squares / df)
            t = t_quantile(0.995, df)
            between, pairs, beyond, farthest = [], 0, 0, 0.0
            for spp in budgets:
                cells = [job[(scene, spp)] for job in jobs if (scene, spp) in job]
                if len(cells) < 2:
                    continue
                n = statistics.fmean(len(c) for c in cells)
                means = [statistics.fmean(c) for c in cells]
                between.append(statistics.variance(means) - seed_sd**2 / n)
                for a, b in itertools.combinations(cells, 2):
                    z = abs(statistics.fmean(a) - statistics.fmean(b)) / seed_sd
                    limit = t * math.sqrt(1 / len(a) + 1 / len(b) + 2 * args.job_noise**2)
                    pairs += 1
                    beyond += z > limit
                    farthest = max(farthest, z)
            if not between:
                continue
            job_sd = math.sqrt(max(0.0, statistics.fmean(between)))
            n = statistics.fmean(len(c) for job in jobs for (s, _), c in job.items() if s == scene)
            k_none = math.sqrt(max(0.0, ((farthest / t) ** 2 - 2 / n) / 2))
            print(f"| {program} | {scene} | {len(jobs)} | {100 * seed_sd:.1f} % ({df}) | {100 * job_sd:.1f} % "
                  f"| {job_sd / seed_sd:.2f} | {pairs} | {farthest:.1f} | {beyond} | {k_none:.2f} |")


if __name__ == "__main__":
    main()
