// FBKSD results viewer: charts. For one scene and metric, log–log lines of
// the metric against spp or against time (one line per technique, a
// legend that toggles lines, values on hover), and the equal-time view:
// each technique's error at the cost of the cheapest technique at each
// budget, as the ranking found it (sdk/exchange/src/ranking.rs: the
// document's equal-time cells; nothing is recomputed here). Each chart
// exports as SVG and PNG, its data as CSV.
"use strict";
(function () {
  const FBKSD = (window.FBKSD = window.FBKSD || {});
  const SVG = "http://www.w3.org/2000/svg";
  const PALETTE = ["#2454a6", "#d1495b", "#00798c", "#edae49", "#66a182", "#8d6a9f", "#3d405b", "#e07a5f", "#81b29a", "#9c6644", "#f28482", "#1b998b"];
  FBKSD.colourOf = (i) => PALETTE[i % PALETTE.length];

  // "cost" is the equal-time ranking's axis (sdk/exchange/src/cost.rs): the
  // technique's CPU time after its hello plus its samples at the scene's
  // render rate; "result" the wall time to the result beside it.
  const TIME_MEASURES = {
    cost: { label: "cost (CPU)", of: (r) => r.cost_ms || r.time_ms || r.wall_ms },
    result: { label: "wall time to result", of: (r) => r.time_ms || r.wall_ms },
    technique: { label: "technique time", of: (r) => r.technique_ms },
    total: { label: "render + technique time", of: (r) => r.technique_ms + r.render_ms },
    cpu: { label: "CPU time", of: (r) => r.cpu_ms },
  };
  FBKSD.TIME_MEASURES = TIME_MEASURES;
  // The time axis of a chart: at equal time always the ranking's, the cost.
  FBKSD.timeMeasure = (kind, measure) => TIME_MEASURES[kind === "equal_time" ? "cost" : measure] || TIME_MEASURES.cost;
  // Times are CPU times of one runner class: a technique measured on
  // another, or on a runner whose calibration had drifted from its
  // class's, would be compared on its machine, not on its work. The server
  // decides which (leaderboard::untimed_sets); this says why a technique
  // is off the time axis ("" when it is on it).
  FBKSD.untimed = (t) => t.untimed || "";

  // The series of a chart: [{key, name, colour, points: [{x, y, spp}]}].
  // kind: "spp", "time" or "equal_time" (whose points are the ranking's
  // equal-time cells of the scene and metric; the time axis is then the cost).
  FBKSD.chartSeries = function (doc, scene, metric, kind, measure) {
    const time = FBKSD.timeMeasure(kind, measure);
    const cells = kind === "equal_time" ? ((doc.rankings && doc.rankings.equal_time) || []).filter((c) => c.scene === scene && c.metric === metric) : [];
    return doc.techniques.map((t, i) => {
      let points;
      if (kind === "equal_time") {
        points = cells
          .flatMap((c) => c.places.filter((p) => p.technique === t.key).map((p) => ({ x: c.at.ms, y: p.mean, spp: p.spp ?? c.at.spp })))
          .sort((a, b) => a.x - b.x);
      } else {
        points = t.runs
          .filter((r) => r.scene === scene && r.status === "ok" && typeof r.metrics[metric] === "number")
          .map((r) => ({ x: kind === "spp" ? r.spp : time.of(r), y: r.metrics[metric], spp: r.spp }))
          .filter((p) => p.x > 0)
          .sort((a, b) => a.x - b.x);
      }
      const untimed = kind !== "spp" && FBKSD.untimed(t);
      const name = FBKSD.techniqueLabel(t) + (untimed ? " (" + untimed + ": not on the time axis)" : "");
      return { key: t.key, name, colour: FBKSD.colourOf(i), points: untimed ? [] : points };
    });
  };

  function el(name, attrs, text) {
    const e = document.createElementNS(SVG, name);
    for (const k in attrs) e.setAttribute(k, attrs[k]);
    if (text !== undefined) e.textContent = text;
    return e;
  }

  function decades(lo, hi) {
    const a = Math.floor(Math.log10(lo)), b = Math.ceil(Math.log10(hi));
    return { a, b: b === a ? a + 1 : b };
  }

  function numberText(v) {
    return Math.abs(v) >= 1e4 || Math.abs(v) < 1e-3 ? v.toExponential(3) : String(Number(v.toPrecision(4)));
  }
  FBKSD.numberText = numberText;

  // Draws a log–log chart into an <svg>; hidden series keep their legend entry.
  FBKSD.drawChart = function (svg, series, opts) {
    const W = 560, H = 340, L = 70, R = 16, T = 28, B = 48;
    svg.setAttribute("xmlns", SVG);
    svg.setAttribute("viewBox", "0 0 " + W + " " + H);
    svg.setAttribute("width", W);
    svg.setAttribute("height", H);
    svg.replaceChildren();
    svg.append(el("rect", { x: 0, y: 0, width: W, height: H, fill: "#fff" }));
    svg.append(el("text", { x: L, y: 18, "font-size": 13, "font-family": "sans-serif", "font-weight": 600 }, opts.title));
    // A log scale has no place for values ≤ 0: they are left out of the drawing (the CSV has them) and counted.
    const visible = series.filter((s) => !opts.hidden.has(s.key));
    const shown = visible.map((s) => ({ ...s, points: s.points.filter((p) => p.x > 0 && p.y > 0) })).filter((s) => s.points.length);
    const all = shown.flatMap((s) => s.points);
    const left = visible.reduce((n, s) => n + s.points.length, 0) - all.length;
    if (left) svg.append(el("text", { x: W - R, y: 18, "text-anchor": "end", "font-size": 11, "font-family": "sans-serif", fill: "#667085", class: "left-out" }, left + (left === 1 ? " value ≤ 0 not drawn" : " values ≤ 0 not drawn")));
    if (!all.length) {
      svg.append(el("text", { x: W / 2, y: H / 2, "text-anchor": "middle", "font-family": "sans-serif", fill: "#667085" }, "no values to draw"));
      return;
    }
    const xs = decades(Math.min(...all.map((p) => p.x)), Math.max(...all.map((p) => p.x)));
    const ys = decades(Math.min(...all.map((p) => p.y)), Math.max(...all.map((p) => p.y)));
    const X = (x) => L + ((Math.log10(x) - xs.a) / (xs.b - xs.a)) * (W - L - R);
    const Y = (y) => H - B - ((Math.log10(y) - ys.a) / (ys.b - ys.a)) * (H - T - B);
    const axes = el("g", { "font-size": 11, "font-family": "sans-serif", fill: "#667085" });
    for (let d = xs.a; d <= xs.b; d++) {
      axes.append(el("line", { x1: X(10 ** d), x2: X(10 ** d), y1: T, y2: H - B, stroke: "#e4e7ec" }));
      axes.append(el("text", { x: X(10 ** d), y: H - B + 16, "text-anchor": "middle" }, "1e" + d));
    }
    for (let d = ys.a; d <= ys.b; d++) {
      axes.append(el("line", { x1: L, x2: W - R, y1: Y(10 ** d), y2: Y(10 ** d), stroke: "#e4e7ec" }));
      axes.append(el("text", { x: L - 6, y: Y(10 ** d) + 4, "text-anchor": "end" }, "1e" + d));
    }
    axes.append(el("text", { x: (L + W - R) / 2, y: H - 10, "text-anchor": "middle", fill: "#1d2430" }, opts.xLabel));
    axes.append(el("text", { x: 14, y: (T + H - B) / 2, "text-anchor": "middle", fill: "#1d2430", transform: "rotate(-90 14 " + (T + H - B) / 2 + ")" }, opts.yLabel));
    svg.append(axes);
    for (const s of shown) {
      const g = el("g", { class: "series", "data-key": s.key, "data-name": s.name });
      g.append(el("polyline", {
        points: s.points.map((p) => X(p.x).toFixed(2) + "," + Y(p.y).toFixed(2)).join(" "),
        fill: "none", stroke: s.colour, "stroke-width": s.key === opts.highlight ? 3 : 1.6,
      }));
      for (const p of s.points) {
        const dot = el("circle", { cx: X(p.x).toFixed(2), cy: Y(p.y).toFixed(2), r: 3.5, fill: s.colour });
        dot.append(el("title", {}, s.name + ": " + numberText(p.y) + " at " + opts.xLabel + " " + numberText(p.x) + " (" + p.spp + " spp)"));
        g.append(dot);
      }
      svg.append(g);
    }
  };

  FBKSD.chartCsv = function (series, xLabel, yLabel) {
    // Technique names are their authors' own: a cell that starts like a
    // formula (= + - @, tab, return) is kept text with a leading apostrophe,
    // or a spreadsheet opening the file would run it.
    const quote = (s) => {
      const text = String(s);
      return '"' + (/^[=+\-@\t\r]/.test(text) ? "'" + text : text).replace(/"/g, '""') + '"';
    };
    const lines = ["technique,spp," + quote(xLabel) + "," + quote(yLabel)];
    for (const s of series) for (const p of s.points) lines.push([quote(s.name), p.spp, p.x, p.y].join(","));
    return lines.join("\n") + "\n";
  };

  FBKSD.svgText = (svg) => new XMLSerializer().serializeToString(svg);

  FBKSD.svgToPng = function (svg) {
    return new Promise((resolve, reject) => {
      const img = new Image();
      const url = URL.createObjectURL(new Blob([FBKSD.svgText(svg)], { type: "image/svg+xml" }));
      img.onload = () => {
        const scale = 2;
        const c = document.createElement("canvas");
        c.width = img.naturalWidth * scale;
        c.height = img.naturalHeight * scale;
        const g = c.getContext("2d");
        g.scale(scale, scale);
        g.drawImage(img, 0, 0);
        URL.revokeObjectURL(url);
        c.toBlob((blob) => (blob ? resolve(blob) : reject(new Error("PNG export failed"))), "image/png");
      };
      img.onerror = () => reject(new Error("the SVG did not load"));
      img.src = url;
    });
  };

  FBKSD.download = function (name, blob) {
    const a = document.createElement("a");
    a.href = URL.createObjectURL(blob);
    a.download = name;
    document.body.append(a);
    a.click();
    a.remove();
    setTimeout(() => URL.revokeObjectURL(a.href), 10000);
  };
})();
