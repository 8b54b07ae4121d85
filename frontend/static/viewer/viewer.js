// FBKSD results viewer: the page. It reads the viewer's document
// (sdk/exchange/src/viewer.rs) from window.FBKSD_DOCUMENT (a static folder
// written by `fbksd results page`) or from the address in the container's
// data-document (the service), builds the top bar, and wires the image
// comparison (images.js), the charts (charts.js) and the tables
// (tables.js). Everything is drawn from the document; pixels load lazily
// for the scene and spp on screen.
//
// Keys: f flips A and B, s toggles the split view, [ and ] change the
// exposure by half a stop, + and - zoom at the cursor, 0 shows the
// reference as A, 1–9 a technique, r fits the image again.
"use strict";
(function () {
  const FBKSD = (window.FBKSD = window.FBKSD || {});

  function h(tag, attrs, ...children) {
    const e = document.createElement(tag);
    for (const k in attrs || {}) {
      if (k === "class") e.className = attrs[k];
      else if (k.startsWith("on")) e.addEventListener(k.slice(2), attrs[k]);
      else e.setAttribute(k, attrs[k]);
    }
    e.append(...children.filter((c) => c !== null && c !== undefined));
    return e;
  }

  function options(select, items, value) {
    select.replaceChildren(...items.map(([v, label]) => h("option", { value: v }, label)));
    if (items.some(([v]) => String(v) === String(value))) select.value = value;
  }

  class Viewer {
    constructor(root, doc) {
      this.root = root;
      this.doc = doc;
      // The address may name a scene and spp: #scene=<name>&spp=<n>.
      const wanted = new URLSearchParams(location.hash.slice(1));
      const named = doc.scenes.find((x) => x.name === wanted.get("scene"));
      const first = named ? named.name : doc.scenes[0] ? doc.scenes[0].name : null;
      const own = doc.techniques.find((t) => t.key === doc.highlight) || doc.techniques[0];
      this.state = {
        scene: first,
        spp: Number(wanted.get("spp")) || null,
        a: own ? own.key : "reference",
        b: "reference",
        layer: "image",
        mode: "single",
        flipped: false,
        split: 0.5,
        exposure: 0,
        transfer: "srgb",
        falseColour: false,
        cropSize: 32,
        metric: doc.metrics[0] ? doc.metrics[0].acronym : null,
        chartX: "spp",
        measure: "cost",
        tag: "",
        hidden: new Set(),
      };
      this.build();
      this.comparison = new FBKSD.Comparison(this, this.imagesSection);
      this.selectScene(first);
      this.bindKeys();
    }

    technique(key) {
      return this.doc.techniques.find((t) => t.key === key);
    }

    run(key, scene, spp) {
      const t = this.technique(key);
      return t && t.runs.find((r) => r.scene === scene && r.spp === spp);
    }

    label(key) {
      if (key === "reference") return "Reference";
      if (key.startsWith("reference:")) return "Reference · " + key.slice(10) + " buffer";
      return FBKSD.techniqueLabel(this.technique(key)) || key;
    }

    // What A or B shows: {address, kind, label} or null.
    source(key, layer) {
      const s = this.state;
      if (key === "reference") {
        const scene = this.doc.scenes.find((x) => x.name === s.scene);
        return scene && scene.reference ? { address: scene.reference, kind: "pixels", label: "Reference" } : null;
      }
      // A feature buffer made with the reference (albedo, normal, depth).
      if (key.startsWith("reference:")) {
        const scene = this.doc.scenes.find((x) => x.name === s.scene);
        const address = scene && scene.buffers && scene.buffers[key.slice(10)];
        return address ? { address, kind: "pixels", label: this.label(key) } : null;
      }
      const run = this.run(key, s.scene, s.spp);
      if (!run) return null;
      if (layer === "image") return run.pixels ? { address: run.pixels, kind: "pixels", label: this.label(key) } : null;
      const map = run.error_maps[layer];
      return map ? { address: map, kind: "map", label: this.label(key) + " · " + layer + " error" } : null;
    }

    missingReason(key, layer) {
      if (key === "reference") return "this scene's reference is not stored";
      if (key.startsWith("reference:")) return "this scene has no " + key.slice(10) + " buffer";
      const run = this.run(key, this.state.scene, this.state.spp);
      if (!run) return this.label(key) + " has no run at " + this.state.spp + " spp";
      if (run.status !== "ok") return this.label(key) + ": " + run.status + (run.message ? " (" + run.message + ")" : "");
      return layer === "image" ? "no pixel file for this run" : "no " + layer + " error map for this run";
    }

    // The crop strip: the reference, then every technique, at the current layer.
    cropSources() {
      const s = this.state;
      const entries = [{ key: "reference", label: "Reference", source: this.source("reference", "image") }];
      const metric = s.metric;
      for (const t of this.doc.techniques) {
        const run = this.run(t.key, s.scene, s.spp);
        const v = run && run.metrics[metric];
        entries.push({
          key: t.key,
          label: this.label(t.key),
          note: typeof v === "number" ? metric + " " + FBKSD.numberText(v) : "",
          highlight: t.key === this.doc.highlight,
          source: this.source(t.key, s.layer),
        });
      }
      return entries;
    }

    build() {
      const d = this.doc, s = this.state;
      this.sceneSelect = h("select", { name: "scene", onchange: (e) => this.selectScene(e.target.value) });
      this.sppSelect = h("select", { name: "spp", onchange: (e) => this.set({ spp: Number(e.target.value) }) });
      // Feature buffers any scene has, in the order the document gives them.
      const buffers = [...new Set(d.scenes.flatMap((x) => Object.keys(x.buffers || {})))];
      const sources = [["reference", "Reference"], ...buffers.map((b) => ["reference:" + b, "Reference · " + b + " buffer"]),
        ...d.techniques.map((t) => [t.key, FBKSD.techniqueLabel(t)])];
      this.aSelect = h("select", { name: "a", onchange: (e) => this.set({ a: e.target.value }) });
      options(this.aSelect, sources, s.a);
      this.bSelect = h("select", { name: "b", onchange: (e) => this.set({ b: e.target.value }) });
      options(this.bSelect, sources, s.b);
      this.layerSelect = h("select", { name: "layer", onchange: (e) => this.set({ layer: e.target.value }) });
      options(this.layerSelect, [["image", "image"], ...d.metrics.filter((m) => m.has_error_map).map((m) => [m.acronym, m.acronym + " error map"])], "image");
      this.modeSelect = h("select", { name: "mode", onchange: (e) => this.set({ mode: e.target.value, flipped: false }) });
      options(this.modeSelect, [["single", "A only"], ["split", "split A | B"], ["flip", "flip A/B (f)"]], s.mode);
      this.splitInput = h("input", { type: "range", name: "split", min: 0, max: 1, step: 0.01, value: s.split, oninput: (e) => { s.split = Number(e.target.value); this.comparison.requestDraw(); } });
      this.exposureInput = h("input", { type: "range", name: "exposure", min: -10, max: 10, step: 0.5, value: 0, oninput: (e) => this.set({ exposure: Number(e.target.value) }) });
      this.exposureText = h("output", { class: "exposure" }, "0 EV");
      this.transferSelect = h("select", { name: "transfer", onchange: (e) => this.set({ transfer: e.target.value }) });
      options(this.transferSelect, [["srgb", "sRGB"], ["gamma22", "gamma 2.2"], ["linear", "linear"]], s.transfer);
      this.falseInput = h("input", { type: "checkbox", name: "false_colour", onchange: (e) => this.set({ falseColour: e.target.checked }) });
      this.cropSelect = h("select", { name: "crop", onchange: (e) => { s.cropSize = Number(e.target.value); this.comparison.drawCrops(); this.comparison.requestDraw(); } });
      options(this.cropSelect, [8, 16, 32, 64].map((v) => [v, v + " px"]), s.cropSize);
      const label = (text, control) => h("label", {}, text + " ", control);
      const bar = h("div", { class: "viewer-bar" },
        label("Scene", this.sceneSelect), label("spp", this.sppSelect), label("A", this.aSelect), label("B", this.bSelect),
        label("Show", this.layerSelect), label("View", this.modeSelect), label("Split", this.splitInput),
        label("Exposure", this.exposureInput), this.exposureText, label("Display", this.transferSelect),
        label("False colour", this.falseInput), label("Crops", this.cropSelect));
      this.imagesSection = h("section", { class: "viewer-images" },
        h("div", { class: "stage" }, h("canvas", { class: "main", tabindex: 0 }), h("div", { class: "inspector" })),
        h("p", { class: "image-status muted" }),
        h("p", { class: "muted keys" }, "Wheel or + − zoom, drag pans, a click pins the crops. Keys: f flip, s split, [ ] exposure, 0 reference, 1–9 techniques, r fit."),
        h("div", { class: "crops" }));

      // Charts.
      this.metricSelect = h("select", { name: "metric", onchange: (e) => this.set({ metric: e.target.value }) });
      options(this.metricSelect, d.metrics.map((m) => [m.acronym, m.acronym + (m.lower_is_better ? " ↓" : " ↑")]), s.metric);
      this.chartXSelect = h("select", { name: "chart_x", onchange: (e) => this.set({ chartX: e.target.value }) });
      options(this.chartXSelect, [["spp", "against spp"], ["time", "against time"], ["equal_time", "at equal time"]], s.chartX);
      this.measureSelect = h("select", { name: "measure", onchange: (e) => this.set({ measure: e.target.value }) });
      options(this.measureSelect, Object.entries(FBKSD.TIME_MEASURES).map(([k, v]) => [k, v.label]), s.measure);
      this.chart = document.createElementNS("http://www.w3.org/2000/svg", "svg");
      this.chart.classList.add("chart");
      this.legend = h("ul", { class: "legend" });
      const exportBar = h("div", { class: "exports" },
        h("button", { type: "button", onclick: () => FBKSD.download(this.exportName("svg"), new Blob([FBKSD.svgText(this.chart)], { type: "image/svg+xml" })) }, "SVG"),
        h("button", { type: "button", onclick: () => FBKSD.svgToPng(this.chart).then((b) => FBKSD.download(this.exportName("png"), b)) }, "PNG"),
        h("button", { type: "button", onclick: () => FBKSD.download(this.exportName("csv"), new Blob([this.chartCsv()], { type: "text/csv" })) }, "CSV"));
      const chartSection = h("section", { class: "viewer-charts" },
        h("h2", {}, "Error, samples and time"),
        h("div", { class: "viewer-bar" }, label("Metric", this.metricSelect), label("Chart", this.chartXSelect), label("Time", this.measureSelect), exportBar),
        h("div", { class: "chart-row" }, this.chart, this.legend));

      // Ranking and costs.
      this.tagSelect = h("select", { name: "tag", onchange: (e) => this.set({ tag: e.target.value }) });
      const tags = [...new Set(d.scenes.flatMap((x) => x.tags))].sort();
      options(this.tagSelect, [["", "all scenes"], ...tags.map((t) => [t, t])], "");
      this.rankingTable = h("table", { class: "ranking" });
      this.costsTable = h("table", { class: "costs" });
      this.costsTitle = h("h2", {});
      const rankingSection = h("section", { class: "viewer-ranking" },
        h("h2", {}, "Ranking"),
        h("div", { class: "viewer-bar" }, label("Scenes", this.tagSelect), h("span", { class: "muted" }, "by the chart's metric; mean rank over every scene and spp, ties share places, a missing run counts as last")),
        this.rankingTable);
      const costsSection = h("section", { class: "viewer-costs" }, this.costsTitle, this.costsTable);
      this.root.replaceChildren(bar, this.imagesSection, chartSection, rankingSection, costsSection);
      options(this.sceneSelect, d.scenes.map((x) => [x.name, x.name + (x.tags.length ? " (" + x.tags.join(", ") + ")" : "")]), s.scene);
    }

    exportName(ext) {
      const s = this.state;
      return ["fbksd", s.scene, s.metric, s.chartX].join("-") + "." + ext;
    }

    chartSeries() {
      const s = this.state;
      return FBKSD.chartSeries(this.doc, s.scene, s.metric, s.chartX, s.measure);
    }

    chartLabels() {
      const s = this.state;
      const time = FBKSD.timeMeasure(s.chartX, s.measure).label + " (ms)";
      return { x: s.chartX === "spp" ? "samples per pixel" : time, y: s.metric };
    }

    chartCsv() {
      const l = this.chartLabels();
      return FBKSD.chartCsv(this.chartSeries().filter((x) => !this.state.hidden.has(x.key)), l.x, l.y);
    }

    selectScene(name) {
      const s = this.state;
      s.scene = name;
      const spps = [...new Set(this.doc.techniques.flatMap((t) => t.runs.filter((r) => r.scene === name).map((r) => r.spp)))].sort((a, b) => a - b);
      if (!spps.includes(s.spp)) s.spp = spps[0] ?? null;
      options(this.sppSelect, spps.map((v) => [v, String(v)]), s.spp);
      this.sceneSelect.value = name;
      this.refresh();
    }

    set(change) {
      Object.assign(this.state, change);
      if ("scene" in change) return this.selectScene(change.scene);
      this.refresh(change);
    }

    refresh(change) {
      const s = this.state;
      this.exposureText.textContent = (s.exposure > 0 ? "+" : "") + s.exposure + " EV";
      this.exposureInput.value = s.exposure;
      this.aSelect.value = s.a;
      this.bSelect.value = s.b;
      this.modeSelect.value = s.mode;
      const imagesChanged = !change || ["spp", "a", "b", "layer", "mode", "exposure", "transfer", "falseColour", "metric"].some((k) => k in change);
      // `showing` settles once A (and B) are on screen; benchmarks wait on it.
      if (imagesChanged) this.showing = this.comparison.show();
      if (!change || ["metric", "chartX", "measure", "hidden"].some((k) => k in change)) this.drawChart();
      if (!change || ["metric", "tag"].some((k) => k in change)) this.drawRanking();
      if (!change) this.drawCosts();
    }

    drawChart() {
      const s = this.state;
      const series = this.chartSeries();
      const l = this.chartLabels();
      const what = { spp: "against spp", time: "against time", equal_time: "at equal time" }[s.chartX];
      FBKSD.drawChart(this.chart, series, { title: s.scene + ": " + s.metric + " " + what, xLabel: l.x, yLabel: l.y, hidden: s.hidden, highlight: this.doc.highlight });
      this.legend.replaceChildren(...series.map((x) => {
        const box = h("input", { type: "checkbox", onchange: (e) => {
          if (e.target.checked) s.hidden.delete(x.key);
          else s.hidden.add(x.key);
          this.refresh({ hidden: true });
        } });
        box.checked = !s.hidden.has(x.key);
        return h("li", {}, h("label", {}, box, h("span", { class: "swatch", style: "background:" + x.colour }), " " + x.name));
      }));
      this.measureSelect.disabled = s.chartX !== "time";
    }

    drawRanking() {
      const s = this.state;
      const scenes = this.doc.scenes.filter((x) => !s.tag || x.tags.includes(s.tag)).map((x) => x.name);
      FBKSD.drawRanking(this.rankingTable, this.doc, scenes, s.metric);
    }

    drawCosts() {
      this.costsTitle.textContent = "Runs on " + this.state.scene;
      FBKSD.drawCosts(this.costsTable, this.doc, this.state.scene);
    }

    bindKeys() {
      document.addEventListener("keydown", (e) => {
        if (e.target.closest && e.target.closest("select, input, textarea")) return;
        const s = this.state;
        if (e.key === "f") {
          if (s.mode !== "flip") this.set({ mode: "flip", flipped: true });
          else {
            s.flipped = !s.flipped;
            this.comparison.requestDraw();
            this.comparison.inspect();
          }
        } else if (e.key === "s") this.set({ mode: s.mode === "split" ? "single" : "split" });
        else if (e.key === "[") this.set({ exposure: s.exposure - 0.5 });
        else if (e.key === "]") this.set({ exposure: s.exposure + 0.5 });
        else if (e.key === "+" || e.key === "=" || e.key === "-") {
          const c = this.comparison, canvas = c.canvas;
          const at = c.pointer || { x: canvas.clientWidth / 2, y: canvas.clientHeight / 2 };
          c.zoomAt(at.x, at.y, e.key === "-" ? 0.5 : 2);
        } else if (e.key === "r") {
          this.comparison.view = null;
          this.comparison.show();
        } else if (e.key === "0") this.set({ a: "reference" });
        else if (/^[1-9]$/.test(e.key)) {
          const t = this.doc.techniques[Number(e.key) - 1];
          if (t) this.set({ a: t.key });
        } else return;
        e.preventDefault();
      });
    }
  }

  FBKSD.Viewer = Viewer;

  async function start() {
    const root = document.getElementById("fbksd-viewer");
    if (!root) return;
    try {
      const doc = window.FBKSD_DOCUMENT || (await (await fetch(root.dataset.document, { credentials: "same-origin" })).json());
      if (doc.format !== "fbksd-viewer") throw new Error("not a viewer document");
      FBKSD.viewer = new Viewer(root, doc);
    } catch (e) {
      root.textContent = "The viewer could not start: " + (e.message || e);
    }
  }
  if (document.readyState === "loading") document.addEventListener("DOMContentLoaded", start);
  else start();
})();
