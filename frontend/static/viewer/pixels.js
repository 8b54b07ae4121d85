// FBKSD results viewer: loading pixel files (.fbpx) and tone mapping them.
//
// A pixel file is the gzip of a 20-byte header ("FBPX", version, width,
// height, channels; little-endian u32) and the image's float32 values,
// channel by channel, split into four byte planes (see
// sdk/exchange/src/pixels.rs). The browser's own DecompressionStream undoes
// the gzip, so no library is needed. From a server the files are fetched;
// from a folder opened at file:// (where fetch is refused) each is a script
// that calls fbksdPixels(address, base64).
"use strict";
(function () {
  const FBKSD = (window.FBKSD = window.FBKSD || {});

  // address → Promise<Pixels>, least recently asked for first; at most
  // MAX_CACHED_BYTES of pixels are kept (a session that steps through
  // every scene and technique would otherwise keep every image).
  const cache = new Map();
  const cachedBytes = new Map(); // address → bytes, once loaded
  const MAX_CACHED_BYTES = 768 * 1024 * 1024;
  // The most values one pixel file may hold, as the SDK writes them
  // (sdk/exchange/src/pixels.rs, MAX_FLOATS): its header says how many
  // before the values are decompressed.
  const MAX_VALUES = 3 * 2 ** 26;
  // The gzip is fed to the decompressor this many bytes at a time: a
  // decompressor inflates each input chunk whole before the reader sees
  // any of it, and deflate inflates up to about 1000×.
  const SLICE = 16 * 1024;
  const pendingScripts = new Map(); // address → resolve(bytes)

  window.fbksdPixels = function (address, base64) {
    const resolve = pendingScripts.get(address);
    if (!resolve) return;
    pendingScripts.delete(address);
    const text = atob(base64);
    const bytes = new Uint8Array(text.length);
    for (let i = 0; i < text.length; i++) bytes[i] = text.charCodeAt(i);
    resolve(bytes.buffer);
  };

  function loadScript(address) {
    return new Promise((resolve, reject) => {
      pendingScripts.set(address, resolve);
      const script = document.createElement("script");
      script.src = address;
      script.onerror = () => {
        pendingScripts.delete(address);
        reject(new Error("could not load " + address));
      };
      script.onload = () => script.remove();
      document.head.appendChild(script);
    });
  }

  async function fetchBytes(address) {
    const response = await fetch(address, { credentials: "same-origin" });
    if (!response.ok) throw new Error(address + ": HTTP " + response.status);
    return response.arrayBuffer();
  }

  // Undoes the gzip, reading no more than the header announces: a file
  // uploaded by a runner could be a few kilobytes that decompress to
  // gigabytes, and the tab would hold them all before the size was checked.
  async function gunzip(buffer, address) {
    const input = new Uint8Array(buffer);
    let offset = 0;
    const slices = new ReadableStream(
      {
        pull(controller) {
          if (offset >= input.length) return controller.close();
          controller.enqueue(input.slice(offset, offset + SLICE));
          offset += SLICE;
        },
      },
      { highWaterMark: 0 }
    );
    const reader = slices.pipeThrough(new DecompressionStream("gzip")).getReader();
    const stop = () => reader.cancel().catch(() => {});
    const header = new Uint8Array(20);
    let raw = null, filled = 0;
    for (;;) {
      const { done, value } = await reader.read();
      if (done) break;
      let chunk = value;
      if (!raw) {
        const take = Math.min(20 - filled, chunk.length);
        header.set(chunk.subarray(0, take), filled);
        filled += take;
        chunk = chunk.subarray(take);
        if (filled < 20) continue;
        const view = new DataView(header.buffer);
        const n = view.getUint32(8, true) * view.getUint32(12, true) * view.getUint32(16, true);
        if (n > MAX_VALUES) {
          stop();
          throw new Error(address + ": its header says " + n + " values, more than the viewer opens (" + MAX_VALUES + ")");
        }
        raw = new Uint8Array(20 + 4 * n);
        raw.set(header);
      }
      if (filled + chunk.length > raw.length) {
        stop();
        throw new Error(address + ": longer than its header says");
      }
      raw.set(chunk, filled);
      filled += chunk.length;
    }
    if (!raw) throw new Error(address + ": not an FBKSD pixel file");
    return filled === raw.length ? raw.buffer : raw.buffer.slice(0, filled);
  }

  // Parses a pixel file as it was stored (gzip), bounded by its header.
  FBKSD.decodePixels = async (buffer, address) => parse(await gunzip(buffer, address), address);

  function keep(address, pixels) {
    cachedBytes.set(address, pixels.planar.byteLength);
    let total = 0;
    for (const bytes of cachedBytes.values()) total += bytes;
    for (const oldest of cache.keys()) {
      if (total <= MAX_CACHED_BYTES || oldest === address) break;
      if (!cachedBytes.has(oldest)) continue; // still loading: it holds nothing yet
      total -= cachedBytes.get(oldest);
      cache.delete(oldest);
      cachedBytes.delete(oldest);
    }
  }

  // Parses a decompressed pixel file into planar float32 channels.
  function parse(raw, address) {
    const view = new DataView(raw);
    const magic = String.fromCharCode(view.getUint8(0), view.getUint8(1), view.getUint8(2), view.getUint8(3));
    if (magic !== "FBPX") throw new Error(address + ": not an FBKSD pixel file");
    const version = view.getUint32(4, true);
    if (version !== 1) throw new Error(address + ": pixel file version " + version + " is not supported");
    const width = view.getUint32(8, true), height = view.getUint32(12, true), channels = view.getUint32(16, true);
    const n = width * height * channels;
    if (raw.byteLength !== 20 + 4 * n) throw new Error(address + ": size does not match its header");
    const planes = new Uint8Array(raw, 20);
    const bytes = new Uint8Array(4 * n);
    for (let k = 0; k < 4; k++) {
      const plane = planes.subarray(k * n, (k + 1) * n);
      for (let i = 0, j = k; i < n; i++, j += 4) bytes[j] = plane[i];
    }
    // Float32Array reads the platform's byte order; every browser platform is little-endian.
    return { width, height, channels, planar: new Float32Array(bytes.buffer), address };
  }

  // The pixels at `address` (cached), loaded as the document's delivery says.
  FBKSD.loadPixels = function (address, delivery) {
    let pixels = cache.get(address);
    if (pixels) {
      cache.delete(address); // asked for again: the most recent
    } else {
      const bytes = delivery === "script" ? loadScript(address) : fetchBytes(address);
      pixels = bytes.then((buffer) => FBKSD.decodePixels(buffer, address));
      pixels.then(
        (loaded) => cache.get(address) === pixels && keep(address, loaded),
        () => cache.get(address) === pixels && cache.delete(address)
      );
    }
    cache.set(address, pixels);
    return pixels;
  };

  // An error map (PNG) as an image element, cached.
  const maps = new Map();
  FBKSD.loadMap = function (address) {
    if (!maps.has(address)) {
      maps.set(
        address,
        new Promise((resolve, reject) => {
          const img = new Image();
          img.onload = () => resolve(img);
          img.onerror = () => {
            maps.delete(address);
            reject(new Error("could not load " + address));
          };
          img.src = address;
        })
      );
    }
    return maps.get(address);
  };

  // The sRGB transfer function, as sdk/iqa/src/image.rs applies it.
  function srgb(v) {
    if (!(v > 0)) return 0;
    if (v >= 1) return 1;
    return v <= 0.0031308 ? v * 12.92 : 1.055 * Math.pow(v, 1 / 2.4) - 0.055;
  }
  FBKSD.srgb = srgb;

  const TRANSFERS = {
    srgb: srgb,
    gamma22: (v) => (v > 0 ? Math.min(1, Math.pow(v, 1 / 2.2)) : 0),
    linear: (v) => (v > 0 ? Math.min(1, v) : 0),
  };

  // A perceptually ordered colour ramp (dark blue → teal → yellow), authored
  // here as a few stops linearly interpolated.
  const RAMP = [
    [0.0, 13, 8, 135],
    [0.25, 84, 2, 163],
    [0.5, 33, 145, 140],
    [0.75, 144, 215, 67],
    [1.0, 253, 231, 37],
  ];
  function ramp(t) {
    t = Math.max(0, Math.min(1, t));
    for (let i = 1; i < RAMP.length; i++) {
      if (t <= RAMP[i][0]) {
        const a = RAMP[i - 1], b = RAMP[i], u = (t - a[0]) / (b[0] - a[0]);
        return [a[1] + u * (b[1] - a[1]), a[2] + u * (b[2] - a[2]), a[3] + u * (b[3] - a[3])];
      }
    }
    return RAMP[RAMP.length - 1].slice(1);
  }
  FBKSD.ramp = ramp;

  // The 255 linear values at which the transfer's 8-bit output steps up:
  // output(v) = the number of thresholds <= v, exactly
  // floor(f(v) * 255 + 0.5), found by bisection on f itself. Tone mapping
  // then costs a binary search per channel instead of a pow.
  const thresholdCache = new Map();
  function thresholds(transfer) {
    if (thresholdCache.has(transfer)) return thresholdCache.get(transfer);
    const f = TRANSFERS[transfer] || srgb;
    const byte = (v) => Math.floor(f(v) * 255 + 0.5);
    const out = new Float64Array(255);
    for (let k = 1; k <= 255; k++) {
      let lo = 0, hi = 1;
      for (let i = 0; i < 200 && lo < hi; i++) {
        const mid = (lo + hi) / 2;
        if (mid === lo || mid === hi) break;
        if (byte(mid) >= k) hi = mid;
        else lo = mid;
      }
      out[k - 1] = hi; // the smallest value found whose output is k or more
    }
    thresholdCache.set(transfer, out);
    return out;
  }

  // Tone maps pixels into RGBA bytes: `exposure` in stops, a transfer
  // ("srgb", "gamma22", "linear"), and optionally false colour (the
  // luminance's log2 from -8 to +4 stops around the exposure, on the ramp).
  //
  // `region` ({x, y, width, height}, default the whole image) tone maps a
  // window only, as the crops need; pixels outside the image are dark grey.
  FBKSD.toneMap = function (pixels, exposure, transfer, falseColour, region) {
    const { width, height, channels, planar } = pixels;
    const n = width * height;
    const box = region || { x: 0, y: 0, width, height };
    const out = new Uint8ClampedArray(4 * box.width * box.height);
    // Output position o (in bytes) of every image pixel i of the box; -1 outside.
    const each = (fn) => {
      for (let by = 0, o = 0; by < box.height; by++) {
        const y = box.y + by;
        for (let bx = 0; bx < box.width; bx++, o += 4) {
          const x = box.x + bx;
          if (x < 0 || y < 0 || x >= width || y >= height) {
            out[o] = 43;
            out[o + 1] = 47;
            out[o + 2] = 54;
            out[o + 3] = 255;
          } else {
            fn(y * width + x, o);
          }
        }
      }
    };
    const scale = Math.pow(2, exposure);
    const r = planar.subarray(0, n);
    const g = channels > 1 ? planar.subarray(n, 2 * n) : r;
    const b = channels > 2 ? planar.subarray(2 * n, 3 * n) : r;
    if (falseColour) {
      const colours = [];
      for (let i = 0; i < 256; i++) colours.push(ramp(i / 255).map((c) => Math.floor(c + 0.5)));
      each((i, o) => {
        const y = scale * (0.2126 * r[i] + 0.7152 * g[i] + 0.0722 * b[i]);
        const t = y > 0 ? Math.max(0, Math.min(255, Math.round(((Math.log2(y) + 8) / 12) * 255))) : 0;
        const c = colours[t];
        out[o] = c[0];
        out[o + 1] = c[1];
        out[o + 2] = c[2];
        out[o + 3] = 255;
      });
      return new ImageData(out, box.width, box.height);
    }
    // Thresholds in the image's own units: v * scale >= t  <=>  v >= t / scale.
    const t = thresholds(transfer).map((x) => x / scale);
    const level = (v) => {
      // Binary search: the number of thresholds <= v (NaN gives 0).
      let lo = 0, hi = 255;
      while (lo < hi) {
        const mid = (lo + hi) >> 1;
        if (t[mid] <= v) lo = mid + 1;
        else hi = mid;
      }
      return lo;
    };
    if (!region) {
      // The whole image, the hot path: a table over the top 16 bits of each
      // float (sign, exponent, 7 bits of mantissa) gives the level at once
      // wherever no threshold falls inside that range of floats; else
      // (256 + bucket) sends the value to the binary search.
      const table = new Uint16Array(65536);
      const f32 = new Float32Array(1), u32 = new Uint32Array(f32.buffer);
      for (let bucket = 0; bucket < 65536; bucket++) {
        u32[0] = bucket << 16;
        const first = level(f32[0]);
        u32[0] = (bucket << 16) | 0xffff;
        const last = level(f32[0]);
        table[bucket] = first === last ? first : 256;
      }
      const bits = new Uint32Array(planar.buffer, planar.byteOffset, planar.length);
      const channel = (i) => {
        const l = table[bits[i] >>> 16];
        return l < 256 ? l : level(planar[i]);
      };
      for (let i = 0, o = 0; i < n; i++, o += 4) {
        out[o] = channel(i);
        out[o + 1] = channels > 1 ? channel(n + i) : out[o];
        out[o + 2] = channels > 2 ? channel(2 * n + i) : out[o];
        out[o + 3] = 255;
      }
    } else {
      each((i, o) => {
        out[o] = level(r[i]);
        out[o + 1] = level(g[i]);
        out[o + 2] = level(b[i]);
        out[o + 3] = 255;
      });
    }
    return new ImageData(out, box.width, box.height);
  };

  // The exact values of a pixel.
  FBKSD.valueAt = function (pixels, x, y) {
    const { width, height, channels, planar } = pixels;
    if (x < 0 || y < 0 || x >= width || y >= height) return null;
    const n = width * height, i = y * width + x;
    const out = [];
    for (let c = 0; c < channels; c++) out.push(planar[c * n + i]);
    return out;
  };
})();
