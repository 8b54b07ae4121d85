// FBKSD results viewer: the image comparison. One large canvas shows image
// A (or A and B split by a slider, or a quick flip between them) with
// zoom to single pixels (nearest neighbour) and pan; a strip below shows,
// for the reference and every technique, a crop around the pixel under the
// cursor, all on the same pixel and the same tone mapping (thesis fig. 6.9).
// An inspector prints the exact float values under the cursor.
"use strict";
(function () {
  const FBKSD = (window.FBKSD = window.FBKSD || {});

  // Shortest decimal that reads back as the same float32.
  function float32Text(v) {
    if (!isFinite(v)) return String(v);
    for (let p = 1; p <= 9; p++) {
      const t = v.toPrecision(p);
      if (Math.fround(Number(t)) === v) return String(Number(t));
    }
    return v.toPrecision(9);
  }
  FBKSD.float32Text = float32Text;

  class Comparison {
    // `viewer` gives the document, the state and the sources of images.
    constructor(viewer, root) {
      this.viewer = viewer;
      this.root = root;
      this.canvas = root.querySelector("canvas.main");
      this.inspector = root.querySelector(".inspector");
      this.strip = root.querySelector(".crops");
      this.status = root.querySelector(".image-status");
      this.view = null; // {zoom, x, y}: screen = (image - origin) * zoom
      this.viewScene = null;
      this.cursor = null; // image pixel under the cursor (or pinned)
      this.pinned = false;
      this.shown = { a: null, b: null }; // prepared images on screen
      this.toned = new Map(); // source address + tone → canvas
      this.frame = 0;
      this.drawSerial = 0;
      this.bindInput();
      new ResizeObserver(() => this.requestDraw()).observe(this.canvas);
    }

    toneKey() {
      const s = this.viewer.state;
      return [s.exposure, s.transfer, s.falseColour].join("|");
    }

    // A source ({address, kind: "pixels"|"map", label}) prepared for drawing:
    // its tone-mapped canvas and its pixels (null for error maps).
    async prepare(source) {
      if (!source) return null;
      const key = source.address + "#" + (source.kind === "map" ? "" : this.toneKey());
      if (this.toned.has(key)) return this.toned.get(key);
      const s = this.viewer.state;
      const canvas = document.createElement("canvas");
      let pixels = null;
      if (source.kind === "map") {
        const img = await FBKSD.loadMap(source.address);
        canvas.width = img.naturalWidth;
        canvas.height = img.naturalHeight;
        canvas.getContext("2d").drawImage(img, 0, 0);
      } else {
        pixels = await FBKSD.loadPixels(source.address, this.viewer.doc.delivery);
        canvas.width = pixels.width;
        canvas.height = pixels.height;
        canvas.getContext("2d").putImageData(FBKSD.toneMap(pixels, s.exposure, s.transfer, s.falseColour), 0, 0);
      }
      const prepared = { source, canvas, pixels, width: canvas.width, height: canvas.height };
      // Only the current tone mapping is kept (older ones are dropped).
      const tone = this.toneKey();
      for (const k of [...this.toned.keys()]) {
        if (!k.endsWith("#") && !k.endsWith("#" + tone)) this.toned.delete(k);
      }
      this.toned.set(key, prepared);
      return prepared;
    }

    // Shows the state's A and B; then fills the crop strip.
    async show() {
      const serial = ++this.drawSerial;
      const s = this.viewer.state;
      const sourceA = this.viewer.source(s.a, s.layer);
      const sourceB = s.mode === "single" ? null : this.viewer.source(s.b, s.layer);
      this.status.textContent = sourceA ? "loading " + sourceA.label + "…" : "no image: " + this.viewer.missingReason(s.a, s.layer);
      let a, b;
      try {
        [a, b] = await Promise.all([this.prepare(sourceA), this.prepare(sourceB)]);
      } catch (e) {
        if (serial === this.drawSerial) this.status.textContent = String(e.message || e);
        return;
      }
      if (serial !== this.drawSerial) return; // a newer request won
      this.shown = { a, b };
      if (a && (this.viewScene !== s.scene || !this.view)) this.fit(a);
      this.status.textContent = a ? "" : this.status.textContent;
      this.draw();
      this.fillCrops(serial);
    }

    fit(image) {
      const w = this.canvas.clientWidth, h = this.canvas.clientHeight;
      const zoom = Math.min(w / image.width, h / image.height);
      // Whole or power-of-two zoom factors keep pixels square on screen.
      const z = zoom >= 1 ? Math.floor(zoom) : Math.pow(2, Math.floor(Math.log2(zoom)));
      this.view = { zoom: z, x: (w - image.width * z) / 2, y: (h - image.height * z) / 2 };
      this.viewScene = this.viewer.state.scene;
    }

    requestDraw() {
      if (this.frame) return;
      this.frame = requestAnimationFrame(() => {
        this.frame = 0;
        this.draw();
      });
    }

    draw() {
      const c = this.canvas, dpr = window.devicePixelRatio || 1;
      const w = Math.round(c.clientWidth * dpr), h = Math.round(c.clientHeight * dpr);
      if (c.width !== w || c.height !== h) {
        c.width = w;
        c.height = h;
      }
      const g = c.getContext("2d");
      g.setTransform(1, 0, 0, 1, 0, 0);
      g.fillStyle = "#2b2f36";
      g.fillRect(0, 0, w, h);
      const { a, b } = this.shown;
      if (!a || !this.view) return;
      const s = this.viewer.state;
      const v = this.view;
      g.imageSmoothingEnabled = false;
      g.setTransform(v.zoom * dpr, 0, 0, v.zoom * dpr, v.x * dpr, v.y * dpr);
      const first = s.mode === "flip" && s.flipped && b ? b : a;
      g.drawImage(first.canvas, 0, 0);
      if (s.mode === "split" && b) {
        const splitX = s.split * c.clientWidth;
        g.save();
        g.setTransform(1, 0, 0, 1, 0, 0);
        g.beginPath();
        g.rect(splitX * dpr, 0, w - splitX * dpr, h);
        g.clip();
        g.setTransform(v.zoom * dpr, 0, 0, v.zoom * dpr, v.x * dpr, v.y * dpr);
        g.drawImage(b.canvas, 0, 0);
        g.restore();
        g.setTransform(1, 0, 0, 1, 0, 0);
        g.fillStyle = "#fff";
        g.fillRect(splitX * dpr - 1, 0, 2, h);
      }
      if (this.cursor && this.pinned) {
        g.setTransform(dpr, 0, 0, dpr, 0, 0);
        const half = s.cropSize / 2;
        g.strokeStyle = "#ffd400";
        g.lineWidth = 1;
        g.strokeRect(v.x + (this.cursor.x - half) * v.zoom, v.y + (this.cursor.y - half) * v.zoom, s.cropSize * v.zoom, s.cropSize * v.zoom);
      }
      if (FBKSD.firstImageMs === undefined) FBKSD.firstImageMs = performance.now(); // since navigation
      c.dataset.shown = [first.source.address, s.mode, this.toneKey(), v.zoom, Math.round(v.x), Math.round(v.y)].join(" ");
      this.drawCrops();
    }

    // The image pixel at a point of the canvas (CSS pixels).
    pixelAt(px, py) {
      const v = this.view;
      return { x: Math.floor((px - v.x) / v.zoom), y: Math.floor((py - v.y) / v.zoom) };
    }

    // Where an image pixel's top-left corner is on the page (for tests and tools).
    screenOf(x, y) {
      const r = this.canvas.getBoundingClientRect(), v = this.view;
      return { x: r.left + v.x + x * v.zoom, y: r.top + v.y + y * v.zoom, zoom: v.zoom };
    }

    zoomAt(px, py, factor) {
      const v = this.view;
      if (!v) return;
      const zoom = Math.max(1 / 16, Math.min(128, v.zoom * factor));
      v.x = px - ((px - v.x) * zoom) / v.zoom;
      v.y = py - ((py - v.y) * zoom) / v.zoom;
      v.zoom = zoom;
      if (this.pointer && !this.pinned) this.hover(this.pixelAt(this.pointer.x, this.pointer.y));
      this.requestDraw();
    }

    panBy(dx, dy) {
      if (!this.view) return;
      this.view.x += dx;
      this.view.y += dy;
      if (this.pointer && !this.pinned) this.hover(this.pixelAt(this.pointer.x, this.pointer.y));
      this.requestDraw();
    }

    bindInput() {
      const c = this.canvas;
      let drag = null;
      c.addEventListener("wheel", (e) => {
        e.preventDefault();
        const r = c.getBoundingClientRect();
        this.zoomAt(e.clientX - r.left, e.clientY - r.top, e.deltaY < 0 ? 1.25 : 0.8);
      }, { passive: false });
      c.addEventListener("pointerdown", (e) => {
        drag = { x: e.clientX, y: e.clientY, moved: false };
        c.setPointerCapture(e.pointerId);
      });
      c.addEventListener("pointermove", (e) => {
        const r = c.getBoundingClientRect();
        const px = e.clientX - r.left, py = e.clientY - r.top;
        this.pointer = { x: px, y: py };
        if (drag && (drag.moved || Math.abs(e.clientX - drag.x) + Math.abs(e.clientY - drag.y) > 3)) {
          this.panBy(e.clientX - drag.x, e.clientY - drag.y);
          drag = { x: e.clientX, y: e.clientY, moved: true };
          return;
        }
        if (!this.view) return;
        this.hover(this.pixelAt(px, py));
      });
      c.addEventListener("pointerup", (e) => {
        if (drag && !drag.moved && this.view) {
          // A click pins the crops to a pixel; another click frees them.
          const r = c.getBoundingClientRect();
          this.pinned = !this.pinned;
          this.hover(this.pixelAt(e.clientX - r.left, e.clientY - r.top), true);
        }
        drag = null;
      });
    }

    // Moves the crops and the inspector to pixel p.
    hover(p, force) {
      if (this.pinned && !force) return;
      this.cursor = p;
      this.inspect();
      this.requestDraw();
    }

    inspect() {
      const p = this.cursor;
      const { a, b } = this.shown;
      if (!p || !a) return;
      const rows = [["pixel", p.x + ", " + p.y]];
      for (const [name, image] of [["A", a], ["B", b]]) {
        if (!image) continue;
        let text;
        if (image.pixels) {
          const values = FBKSD.valueAt(image.pixels, p.x, p.y);
          text = values ? values.map(float32Text).join("  ") : "outside";
        } else {
          const d = p.x >= 0 && p.y >= 0 && p.x < image.width && p.y < image.height
            ? image.canvas.getContext("2d").getImageData(p.x, p.y, 1, 1).data : null;
          text = d ? "map colour " + d[0] + " " + d[1] + " " + d[2] : "outside";
        }
        rows.push([name + ": " + image.source.label, text]);
      }
      this.inspector.replaceChildren(
        ...rows.map(([k, v]) => {
          const row = document.createElement("div");
          const key = document.createElement("span");
          key.className = "key";
          key.textContent = k;
          const value = document.createElement("output");
          value.textContent = v;
          row.append(key, value);
          return row;
        })
      );
    }

    // One crop per image of the current scene and spp: the reference, then
    // every technique, all at the same layer.
    async fillCrops(serial) {
      const entries = this.viewer.cropSources();
      this.strip.replaceChildren();
      this.crops = [];
      for (const entry of entries) {
        const figure = document.createElement("figure");
        const canvas = document.createElement("canvas");
        canvas.className = "crop";
        const caption = document.createElement("figcaption");
        caption.textContent = entry.label;
        if (entry.note) {
          const note = document.createElement("span");
          note.className = "muted";
          note.textContent = " " + entry.note;
          caption.append(note);
        }
        if (entry.highlight) figure.classList.add("highlight");
        figure.append(canvas, caption);
        this.strip.append(figure);
        const crop = { entry, canvas, image: null };
        this.crops.push(crop);
        if (!entry.source) {
          caption.append(" (no image)");
          continue;
        }
        // Crops tone map only their own window, so they never hold up the main image.
        const loaded = entry.source.kind === "map"
          ? FBKSD.loadMap(entry.source.address).then((img) => ({ map: img, width: img.naturalWidth, height: img.naturalHeight }))
          : FBKSD.loadPixels(entry.source.address, this.viewer.doc.delivery).then((pixels) => ({ pixels, width: pixels.width, height: pixels.height }));
        loaded.then((image) => {
          if (serial !== this.drawSerial) return;
          crop.image = image;
          this.drawCrop(crop);
        }, (e) => caption.append(" (" + (e.message || e) + ")"));
      }
    }

    drawCrops() {
      for (const crop of this.crops || []) this.drawCrop(crop);
    }

    drawCrop(crop) {
      const s = this.viewer.state;
      const size = s.cropSize;
      const scale = Math.max(1, Math.floor(160 / size));
      const c = crop.canvas;
      if (c.width !== size * scale) {
        c.width = size * scale;
        c.height = size * scale;
      }
      const g = c.getContext("2d");
      g.imageSmoothingEnabled = false;
      g.fillStyle = "#2b2f36";
      g.fillRect(0, 0, c.width, c.height);
      if (!crop.image) return;
      const centre = this.cursor || { x: Math.floor(crop.image.width / 2), y: Math.floor(crop.image.height / 2) };
      const x0 = centre.x - size / 2, y0 = centre.y - size / 2;
      if (crop.image.map) {
        g.drawImage(crop.image.map, x0, y0, size, size, 0, 0, size * scale, size * scale);
      } else {
        if (!this.window || this.window.width !== size) {
          this.window = document.createElement("canvas");
          this.window.width = this.window.height = size;
        }
        const region = { x: x0, y: y0, width: size, height: size };
        this.window.getContext("2d").putImageData(FBKSD.toneMap(crop.image.pixels, s.exposure, s.transfer, s.falseColour, region), 0, 0);
        g.drawImage(this.window, 0, 0, size * scale, size * scale);
      }
      c.dataset.centre = centre.x + "," + centre.y;
      c.dataset.scale = scale;
    }
  }

  FBKSD.Comparison = Comparison;
})();
