#!/usr/bin/env python3
"""Ranks the boards of deploy/bench-service-ties.sh runs again with another
`fbksd` binary: each season's published sets (kept in the run's work
directory: board-N.json and sets/) become one results index, ranked by the
board's sort metric (MSE) with `fbksd results show`, and the copies' and the
doubled copy's mean ranks at equal time are printed per season (each group
of techniques/groups.txt: COPIES runs have no doubled copy). The same
measurements under two rules: build `fbksd` at each commit and compare.

    python3 deploy/replay-service-ties.py FBKSD WORK_DIR...

bench-service-ties.sh starts from an empty target/bench-service-ties, so
copy it aside after each run."""
import glob
import json
import os
import re
import subprocess
import sys
import tempfile

if len(sys.argv) < 3:
    sys.exit(__doc__)
fbksd = sys.argv[1]


def season_index(work, board):
    """The season's runs as `fbksd run` records them, MSE only."""
    names = {e["result_id"]: e["technique"] for g in json.load(open(board))["groups"] for e in g["entries"]}
    runs = []
    for set_id, name in names.items():
        for run in json.load(open(f"{work}/sets/{set_id}.json"))["runs"]:
            entry = {k: run[k] for k in ("scene", "spp", "status", "technique_ms", "render_ms", "wall_ms", "cpu_ms",
                                          "peak_memory_bytes", "used_samples")}
            entry.update(technique=name, message=run.get("message", ""), log="", image=None,
                         metrics={"MSE": run["metrics"]["MSE"]})
            entry["repeats"] = [dict(r, metrics={"MSE": r["metrics"]["MSE"]}, log=r.get("log", ""),
                                     image=r.get("image"), message=r.get("message", "")) for r in run["repeats"]]
            runs.append(entry)
    return {"format": "fbksd-results", "version": 1, "runs": runs}


for work in sys.argv[2:]:
    groups = [line.split() for line in open(f"{work}/techniques/groups.txt")]
    boards = sorted(glob.glob(f"{work}/board-*.json"), key=lambda p: int(re.search(r"(\d+)\.json$", p).group(1)))
    rows = []
    for board in boards:
        with tempfile.TemporaryDirectory() as results:
            json.dump(season_index(work, board), open(f"{results}/index.json", "w"))
            shown = subprocess.run([fbksd, "results", "show", "--results", results], capture_output=True, text=True,
                                   check=True).stdout
        standings = shown.split("ranking (mean rank")[1]
        # Rows of the standings: place, technique, mean rank at equal spp, at equal time, …
        rows_at_time = re.finditer(r"^\d+\s+(\S+)\s+[0-9.]+\s+([0-9.]+)", standings, re.M)
        at_time = {m.group(1): float(m.group(2)) for m in rows_at_time}
        for label, *group in groups:
            a, b, *doubled = (at_time[t] for t in group)
            shown = " / ".join(f"{v:.2f}" for v in [a, b, *doubled])
            rows.append((a == b, f"{label}: {shown}{'' if a == b else ' (copies apart)'}"))
    print(f"{work}: copies tied at equal time in {sum(t for t, _ in rows)} of {len(rows)} (season, group) pairs")
    for n, (_, row) in enumerate(rows):
        print(f"  {n // len(groups) + 1}: {row}")
