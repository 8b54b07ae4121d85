// FBKSD results viewer: tables. The ranking over the selected scenes and
// one metric (the rule of sdk/exchange/src/ranking.rs: the mean of each
// technique's rank in every (scene, spp) group, ties sharing the mean of
// their places, a missing value counting as last) with a techniques ×
// scenes grid of per-scene mean ranks; and each run's costs.
"use strict";
(function () {
  const FBKSD = (window.FBKSD = window.FBKSD || {});

  // Ranks: {overall: Map key→mean rank, perScene: Map scene→Map key→mean rank}.
  FBKSD.rank = function (doc, scenes, metric) {
    const info = doc.metrics.find((m) => m.acronym === metric);
    const lower = !info || info.lower_is_better;
    const keys = doc.techniques.map((t) => t.key);
    const n = keys.length;
    const groups = new Map(); // scene|spp → [[key, value]]
    for (const t of doc.techniques) {
      for (const r of t.runs) {
        if (!scenes.has(r.scene)) continue;
        const id = r.scene + "|" + r.spp;
        if (!groups.has(id)) groups.set(id, { scene: r.scene, values: [] });
        const v = r.metrics[metric];
        if (typeof v === "number" && !isNaN(v)) groups.get(id).values.push([t.key, v]);
      }
    }
    const sums = new Map(), perScene = new Map();
    const add = (map, key, rank) => {
      const e = map.get(key) || { sum: 0, count: 0 };
      e.sum += rank;
      e.count += 1;
      map.set(key, e);
    };
    for (const { scene, values } of groups.values()) {
      values.sort((a, b) => (lower ? a[1] - b[1] : b[1] - a[1]));
      if (!perScene.has(scene)) perScene.set(scene, new Map());
      const present = new Set();
      for (let i = 0; i < values.length; ) {
        let j = i;
        while (j + 1 < values.length && values[j + 1][1] === values[i][1]) j++;
        const shared = (i + j) / 2 + 1;
        for (let k = i; k <= j; k++) {
          add(sums, values[k][0], shared);
          add(perScene.get(scene), values[k][0], shared);
          present.add(values[k][0]);
        }
        i = j + 1;
      }
      for (const key of keys) {
        if (!present.has(key)) {
          add(sums, key, n);
          add(perScene.get(scene), key, n);
        }
      }
    }
    const mean = (map) => new Map([...map].map(([k, e]) => [k, e.sum / e.count]));
    return {
      overall: mean(sums),
      perScene: new Map([...perScene].map(([s, m]) => [s, mean(m)])),
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
    const { overall, perScene } = FBKSD.rank(doc, new Set(scenes), metric);
    const n = doc.techniques.length;
    const order = [...doc.techniques].sort((a, b) => (overall.get(a.key) ?? n) - (overall.get(b.key) ?? n) || a.name.localeCompare(b.name));
    const head = document.createElement("tr");
    head.append(cell("th", "#"), cell("th", "Technique"), cell("th", "Mean rank"));
    for (const s of scenes) head.append(cell("th", s, "scene"));
    const body = order.map((t, i) => {
      const row = document.createElement("tr");
      row.dataset.key = t.key;
      if (t.key === doc.highlight) row.className = "highlight";
      const rank = overall.get(t.key);
      row.append(cell("td", String(i + 1)), cell("td", FBKSD.techniqueLabel(t)), cell("td", rank === undefined ? "–" : rank.toFixed(2), "num"));
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

  FBKSD.drawCosts = function (table, doc, scene) {
    const head = document.createElement("tr");
    for (const h of ["Technique", "spp", "Status", "Technique time", "Render time", "Wall", "CPU time", "Peak memory", "Samples", ...doc.metrics.map((m) => m.acronym), "Log"]) {
      head.append(cell("th", h));
    }
    const rows = [];
    for (const t of doc.techniques) {
      for (const r of t.runs.filter((r) => r.scene === scene).sort((a, b) => a.spp - b.spp)) {
        const row = document.createElement("tr");
        if (t.key === doc.highlight) row.className = "highlight";
        const status = cell("td", r.status, r.status === "ok" ? "ok" : "error");
        if (r.message) status.title = r.message;
        row.append(cell("td", FBKSD.techniqueLabel(t)), cell("td", String(r.spp), "num"), status);
        for (const v of [ms(r.technique_ms), ms(r.render_ms), ms(r.wall_ms), ms(r.cpu_ms), bytes(r.peak_memory_bytes), String(r.used_samples)]) {
          row.append(cell("td", v, "num"));
        }
        for (const m of doc.metrics) {
          const v = r.metrics[m.acronym];
          row.append(cell("td", typeof v === "number" ? FBKSD.numberText(v) : "–", "num"));
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
          text.colSpan = 8 + doc.metrics.length;
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
