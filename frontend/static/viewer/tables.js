// FBKSD results viewer: tables. The ranking over the selected scenes and
// one metric, at equal samples and at equal time: the document carries
// every ranking cell (sdk/exchange/src/ranking.rs decides places and ties:
// differences within the noise of the repeats tie, a missing value ranks
// last), and this averages the places over the scenes shown, with a
// techniques × scenes grid of per-scene mean ranks; and each run's costs,
// values with their confidence intervals, times with their spread.
"use strict";
(function () {
  const FBKSD = (window.FBKSD = window.FBKSD || {});

  // Ranks from the document's cells of `kind` ("equal_spp" or "equal_time"):
  // {overall: Map key→mean rank, perScene: Map scene→Map key→mean rank,
  //  ties: Map key→cells tied}.
  FBKSD.rank = function (doc, scenes, metric, kind) {
    // A missing place counts as last among the techniques the cells rank
    // (at equal time, those of the season's runner class), as on the board.
    const ranked = kind === "equal_time" ? doc.techniques.filter((t) => !FBKSD.untimed(t)) : doc.techniques;
    const n = ranked.length;
    const cells = ((doc.rankings && doc.rankings[kind || "equal_spp"]) || []).filter((c) => c.metric === metric && scenes.has(c.scene));
    const sums = new Map(), perScene = new Map(), ties = new Map();
    const add = (map, key, rank) => {
      const e = map.get(key) || { sum: 0, count: 0 };
      e.sum += rank;
      e.count += 1;
      map.set(key, e);
    };
    for (const c of cells) {
      if (!perScene.has(c.scene)) perScene.set(c.scene, new Map());
      for (const p of c.places) {
        add(sums, p.technique, p.place);
        add(perScene.get(c.scene), p.technique, p.place);
        if (p.tied_with && p.tied_with.length) ties.set(p.technique, (ties.get(p.technique) || 0) + 1);
      }
      for (const key of c.missing) {
        add(sums, key, n);
        add(perScene.get(c.scene), key, n);
      }
    }
    const mean = (map) => new Map([...map].map(([k, e]) => [k, e.sum / e.count]));
    return {
      overall: mean(sums),
      perScene: new Map([...perScene].map(([s, m]) => [s, mean(m)])),
      ties,
    };
  };

  // Full names need not be unique: the short name tells them apart.
  FBKSD.techniqueLabel = function (t) {
    if (!t) return null;
    return t.full_name && t.full_name !== t.name ? t.full_name + " (" + t.name + ")" : t.name;
  };

  function cell(tag, text, cls) {
    const e = document.createElement(tag);
    e.textContent = text;
    if (cls) e.className = cls;
    return e;
  }

  // Cell colour: green for first place to red for last.
  function rankColour(rank, n) {
    const t = n > 1 ? (rank - 1) / (n - 1) : 0;
    return "hsl(" + Math.round(130 * (1 - t)) + ", 60%, 85%)";
  }

  FBKSD.drawRanking = function (table, doc, scenes, metric) {
    const { overall, perScene, ties } = FBKSD.rank(doc, new Set(scenes), metric, "equal_spp");
    const atTime = FBKSD.rank(doc, new Set(scenes), metric, "equal_time").overall;
    const n = doc.techniques.length;
    const order = [...doc.techniques].sort((a, b) => (overall.get(a.key) ?? n) - (overall.get(b.key) ?? n) || a.name.localeCompare(b.name));
    const head = document.createElement("tr");
    head.append(cell("th", "#"), cell("th", "Technique"), cell("th", "Mean rank (equal spp)"), cell("th", "Mean rank (equal time)"), cell("th", "Ties"));
    for (const s of scenes) head.append(cell("th", s, "scene"));
    const body = order.map((t, i) => {
      const row = document.createElement("tr");
      row.dataset.key = t.key;
      if (t.key === doc.highlight) row.className = "highlight";
      const rank = overall.get(t.key), time = atTime.get(t.key);
      row.append(
        cell("td", String(i + 1)),
        cell("td", FBKSD.techniqueLabel(t)),
        cell("td", rank === undefined ? "–" : rank.toFixed(2), "num"),
        cell("td", time === undefined ? "–" : time.toFixed(2), "num"),
        cell("td", String(ties.get(t.key) || 0), "num")
      );
      for (const s of scenes) {
        const r = perScene.get(s) && perScene.get(s).get(t.key);
        const c = cell("td", r === undefined ? "–" : r.toFixed(1), "num rank");
        if (r !== undefined) c.style.background = rankColour(r, n);
        row.append(c);
      }
      return row;
    });
    table.replaceChildren(document.createElement("thead"), document.createElement("tbody"));
    table.tHead.append(head);
    table.tBodies[0].append(...body);
  };

  function ms(v) {
    if (!(v > 0)) return "–";
    return v >= 1000 ? (v / 1000).toFixed(2) + " s" : v.toFixed(1) + " ms";
  }
  function bytes(v) {
    if (!(v > 0)) return "–";
    const units = ["B", "KiB", "MiB", "GiB"];
    let i = 0;
    while (v >= 1024 && i < units.length - 1) {
      v /= 1024;
      i++;
    }
    return v.toFixed(i ? 1 : 0) + " " + units[i];
  }

  // What the time columns count, on hover: start-up is shown, and only Cost is the equal-time axis.
  const timeTitles = {
    Cost: "CPU time after the technique's first request, plus its samples at the scene's render rate: the equal-time axis",
    "Start-up": "Technique start to its first request (process start, imports, model loading): shown, not charged",
    "Technique time": "Wall time from the technique's start to its result, less its waits for samples: start-up included",
  };

  FBKSD.drawCosts = function (table, doc, scene) {
    const head = document.createElement("tr");
    for (const h of ["Technique", "spp", "Status", "Seeds", "Cost", "Technique CPU", "Start-up", "Technique time", "Time to result", "Render time", "Wall", "CPU time", "Peak memory", "Samples", ...doc.metrics.map((m) => m.acronym), "Log"]) {
      const th = cell("th", h);
      if (timeTitles[h]) th.title = timeTitles[h];
      head.append(th);
    }
    const rows = [];
    for (const t of doc.techniques) {
      for (const r of t.runs.filter((r) => r.scene === scene).sort((a, b) => a.spp - b.spp)) {
        const row = document.createElement("tr");
        if (t.key === doc.highlight) row.className = "highlight";
        const status = cell("td", r.status, r.status === "ok" ? "ok" : "error");
        if (r.message) status.title = r.message;
        row.append(cell("td", FBKSD.techniqueLabel(t)), cell("td", String(r.spp), "num"), status);
        const cv = (spread) => (spread && r.seeds > 1 ? " (CV " + (spread.cv * 100).toFixed(1) + " %)" : "");
        const timing = r.timing || {};
        for (const v of [String(r.seeds || 1), FBKSD.untimed(t) || ms(r.cost_ms), ms(r.technique_cpu_ms) + cv(timing.technique_cpu), ms(r.startup_ms), ms(r.technique_ms) + cv(timing.technique), ms(r.time_ms), ms(r.render_ms), ms(r.wall_ms), ms(r.cpu_ms), bytes(r.peak_memory_bytes), String(r.used_samples)]) {
          row.append(cell("td", v, "num"));
        }
        for (const m of doc.metrics) {
          const v = r.metrics[m.acronym];
          const i = r.intervals && r.intervals[m.acronym];
          const text = typeof v !== "number" ? "–" : i ? FBKSD.numberText(v) + " ± " + FBKSD.numberText((i.high - i.low) / 2) : FBKSD.numberText(v);
          const c = cell("td", text, "num");
          if (i) c.title = "95 % confidence interval over " + i.n + " seeds: " + FBKSD.numberText(i.low) + " … " + FBKSD.numberText(i.high);
          row.append(c);
        }
        const log = cell("td", "");
        if (r.log) {
          const a = document.createElement("a");
          a.href = r.log;
          a.target = "_blank";
          a.textContent = "log";
          log.append(a);
        }
        row.append(log);
        rows.push(row);
        if (r.status !== "ok" && r.message) {
          const why = document.createElement("tr");
          why.className = "message";
          why.append(cell("td", ""), cell("td", ""));
          const text = cell("td", r.message, "error");
          text.colSpan = 13 + doc.metrics.length;
          why.append(text);
          rows.push(why);
        }
      }
    }
    table.replaceChildren(document.createElement("thead"), document.createElement("tbody"));
    table.tHead.append(head);
    table.tBodies[0].append(...rows);
  };
})();
