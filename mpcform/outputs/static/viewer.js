/* mpcform viewer: plays a run from the JSON in #mpcform-data with the Canvas 2D API (no library,
   no network). 3-D: drag to orbit, shift- or right-drag to pan, wheel to zoom; 2-D: drag to pan,
   wheel to zoom; double-click resets. Space plays/pauses, arrows step one sample. The address's
   hash may hold t=<s>, speed=<0.25..8> and play (e.g. page.html#t=2&speed=4&play). After the first
   frame the page sets <body data-viewer="ok:<samples>"> and logs "viewer-ready" (its self-check). */
(function () {
  "use strict";
  const body = document.body;
  window.addEventListener("error", (e) => { body.dataset.viewer = "error:" + e.message; });

  // ---- data ------------------------------------------------------------------------------
  const D = JSON.parse(document.getElementById("mpcform-data").textContent);
  const n = D.n, dim = D.dim, ts = D.t_s, T = ts.length, stride = n * dim;
  const P = Float64Array.from(D.p_mm, (v) => v / 1000);
  const R = D.ref_mm ? Float64Array.from(D.ref_mm, (v) => v / 1000) : null;
  const F = D.flown ? Float64Array.from(D.flown.p_mm, (v) => v / 1000) : null; // dense true path
  const fts = D.flown ? D.flown.t_s : [];
  const t0 = ts[0], t1 = ts[T - 1], span_t = t1 - t0 || 1;
  const dtMean = T > 1 ? span_t / (T - 1) : 1;
  const TIME_DEC = Math.min(4, Math.max(1, Math.ceil(-Math.log10(dtMean)) + 1));
  const TRAIL_S = 2.0;
  const COL = {
    ink: "#222", axis: "#555", grid: "#ececec", frame: "#b5b5b5", drone: "#1f77b4", far: "#9cc2e2",
    droneEdge: "#0d3b66", bad: "#d62728", edge: "#4a4a4a", ref: "#8c8c8c", fence: "#2e7d32",
    muted: "#777", curve: "#1f77b4", closest: "#c2185b", wind: "#17becf",
  };
  const TRAIL = ["#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22",
    "#17becf"];
  const FONT = '"Helvetica Neue", Helvetica, Arial, "Liberation Sans", "DejaVu Sans", sans-serif';
  const font = (px, weight) => (weight || "") + " " + px + "px " + FONT;

  // ---- time --------------------------------------------------------------------------------
  function sampleAt(time) { // the last sample at or before time
    if (time >= t1) return T - 1;
    let lo = 0, hi = T - 1;
    while (hi - lo > 1) { const mid = (lo + hi) >> 1; if (ts[mid] <= time) lo = mid; else hi = mid; }
    return lo;
  }
  function nearest(time) {
    const k = sampleAt(time);
    return k < T - 1 && time - ts[k] > ts[k + 1] - time ? k + 1 : k;
  }
  function interpolate(arr, time, out) {
    const k = sampleAt(time), a = k < T - 1 ? (time - ts[k]) / (ts[k + 1] - ts[k]) : 0;
    const o0 = k * stride, o1 = Math.min(k + 1, T - 1) * stride;
    for (let j = 0; j < stride; j++) out[j] = arr[o0 + j] + a * (arr[o1 + j] - arr[o0 + j]);
    return out;
  }

  // ---- scene extent (data, reference, obstacles, geofence sides near the flight) -----------
  const LO = new Array(dim).fill(Infinity), HI = new Array(dim).fill(-Infinity);
  const grow = (a, v) => { LO[a] = Math.min(LO[a], v); HI[a] = Math.max(HI[a], v); };
  for (const arr of [P, R, F]) if (arr) for (let j = 0; j < arr.length; j++) grow(j % dim, arr[j]);
  for (const ob of D.obstacles) { // a ball: centre and radius; else its points (outline, surface)
    if (ob.c) { const r = ob.r + ob.clear; for (let a = 0; a < dim; a++) { grow(a, ob.c[a] - r); grow(a, ob.c[a] + r); } }
    for (const q of ob.grown || (ob.mesh ? ob.mesh.v : [])) for (let a = 0; a < dim; a++) grow(a, q[a]);
  }
  let S = Math.max(1e-3, ...LO.map((l, a) => HI[a] - l));
  if (D.fence) {
    for (let a = 0; a < dim; a++) {
      for (const v of [D.fence.min_m[a], D.fence.max_m[a]]) {
        if (v !== null && v >= LO[a] - 0.5 * S && v <= HI[a] + 0.5 * S) grow(a, v);
      }
    }
  }
  S = Math.max(S < 0.01 ? 1 : 0, ...LO.map((l, a) => HI[a] - l));
  const depth = dim === 2 ? 0.01 : 0.1; // of the largest extent: flat axes (a 3-D box) keep some
  for (let a = 0; a < dim; a++) { // pad by 5 % of the axis' own extent
    const mid = (LO[a] + HI[a]) / 2, half = Math.max(0.525 * (HI[a] - LO[a]), depth * S);
    LO[a] = mid - half; HI[a] = mid + half;
  }
  const C = LO.map((l, a) => (l + HI[a]) / 2);
  const RAD = 0.5 * Math.hypot(...LO.map((l, a) => HI[a] - l));

  // ---- axis helpers ------------------------------------------------------------------------
  function ticks(lo, hi, target) {
    const raw = (hi - lo) / Math.max(1, target), p = Math.pow(10, Math.floor(Math.log10(raw)));
    const f = raw / p, step = (f < 1.5 ? 1 : f < 3.5 ? 2 : f < 7.5 ? 5 : 10) * p;
    const values = [];
    for (let i = Math.ceil(lo / step - 1e-9); i * step <= hi + 1e-9 * step; i++) values.push(i * step);
    const dec = Math.max(0, Math.min(6, -Math.floor(Math.log10(step) + 1e-9)));
    return { values, label: (v) => (Math.abs(v) < step * 1e-9 ? 0 : v).toFixed(dec) };
  }
  function fmtValue(v) {
    if (v === null || v === undefined) return "–";
    const a = Math.abs(v);
    if (a === 0) return "0";
    if (a >= 1e4 || a < 1e-2) return v.toExponential(2);
    return v.toPrecision(3);
  }
  function text(g, s, x, y, align, base, f, colour) {
    g.font = f || font(12); g.fillStyle = colour || COL.ink;
    g.textAlign = align || "left"; g.textBaseline = base || "alphabetic";
    g.fillText(s, x, y);
  }
  function fit(canvas) {
    const r = canvas.getBoundingClientRect(), dpr = window.devicePixelRatio || 1;
    const w = Math.max(1, Math.round(r.width * dpr)), h = Math.max(1, Math.round(r.height * dpr));
    if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
    const g = canvas.getContext("2d");
    g.setTransform(dpr, 0, 0, dpr, 0, 0);
    g.fillStyle = "#fff"; g.fillRect(0, 0, r.width, r.height);
    return { g, w: r.width, h: r.height };
  }
  function circle(g, x, y, r) { g.beginPath(); g.arc(x, y, Math.max(0.5, r), 0, 2 * Math.PI); }
  function seg(g, a, b) { g.beginPath(); g.moveTo(a[0], a[1]); g.lineTo(b[0], b[1]); g.stroke(); }

  // ---- state -------------------------------------------------------------------------------
  const $ = (id) => document.getElementById(id);
  const canvas = $("view"), slider = $("slider"), playBtn = $("play");
  const state = { time: t0, playing: false, speed: 1, last: 0 };
  const show = { paths: true, trails: true, ref: !!R, flown: !!F, ids: false };
  const HOME = { az: -Math.PI / 3, el: 0.45, zoom: 1, panX: 0, panY: 0 };
  const view = Object.assign({}, HOME);
  const pos = new Float64Array(stride), ref = new Float64Array(stride);
  const droneR = Math.max(3.5, Math.min(7, 8 - n / 12));

  // ---- projections: both map world points to [x, y, depth toward the viewer, size factor] ----
  function projector(w, h) {
    if (dim === 2) {
      const m = { l: 64, r: 16, t: 14, b: 46 }, room = [w - m.l - m.r, h - m.t - m.b];
      const fit = Math.min(room[0] / (HI[0] - LO[0]), room[1] / (HI[1] - LO[1]));
      const pw = fit * (HI[0] - LO[0]), ph = fit * (HI[1] - LO[1]); // the frame hugs the data
      m.l += (room[0] - pw) / 2; m.t += (room[1] - ph) / 2;
      const s = view.zoom * fit;
      const cx = m.l + pw / 2 + view.panX, cy = m.t + ph / 2 + view.panY;
      const f = (x, y) => [cx + s * (x - C[0]), cy - s * (y - C[1]), 0, 1];
      return { f, s, m, pw, ph, cx, cy, centre: [m.l + pw / 2, m.t + ph / 2] };
    }
    const ca = Math.cos(view.az), sa = Math.sin(view.az), ce = Math.cos(view.el), se = Math.sin(view.el);
    const s = view.zoom * Math.min(w, h - 40) * 0.5 / (1.12 * RAD), dist = 3.5 * RAD;
    const cx = w / 2 + view.panX, cy = (h - 10) / 2 + view.panY;
    const f = (x, y, z) => {
      const dx = x - C[0], dy = y - C[1], dz = z - C[2];
      const xr = -sa * dx + ca * dy, yr = -se * ca * dx - se * sa * dy + ce * dz;
      const zr = ce * ca * dx + ce * sa * dy + se * dz, k = dist / (dist - zr);
      return [cx + s * k * xr, cy - s * k * yr, zr, k];
    };
    return { f, s, cx, cy, centre: [w / 2, (h - 10) / 2] };
  }
  const at = (arr, i) => (dim === 2 ? [arr[i * 2], arr[i * 2 + 1]] : [arr[i * 3], arr[i * 3 + 1], arr[i * 3 + 2]]);

  // ---- the scene ---------------------------------------------------------------------------
  let extent = null; // the 2-D frame's x0, x1, y0, y1 [m], published on the body for tests
  function drawAxes2d(g, pr) {
    const { m, pw, ph, cx, cy, s } = pr;
    const x0 = C[0] + (m.l - cx) / s, x1 = C[0] + (m.l + pw - cx) / s;
    const y0 = C[1] - (m.t + ph - cy) / s, y1 = C[1] - (m.t - cy) / s;
    const tx = ticks(x0, x1, pw / 90), ty = ticks(y0, y1, ph / 70);
    extent = [x0, x1, y0, y1];
    g.lineWidth = 1; g.strokeStyle = COL.grid;
    for (const v of tx.values) seg(g, [pr.f(v, 0)[0], m.t], [pr.f(v, 0)[0], m.t + ph]);
    for (const v of ty.values) seg(g, [m.l, pr.f(0, v)[1]], [m.l + pw, pr.f(0, v)[1]]);
    return () => { // frame, ticks and labels, drawn over the scene
      g.strokeStyle = COL.frame; g.lineWidth = 1; g.strokeRect(m.l, m.t, pw, ph);
      for (const v of tx.values) text(g, tx.label(v), pr.f(v, 0)[0], m.t + ph + 16, "center", "alphabetic", font(11), COL.axis);
      for (const v of ty.values) text(g, ty.label(v), m.l - 6, pr.f(0, v)[1], "right", "middle", font(11), COL.axis);
      text(g, "x [m]", m.l + pw / 2, m.t + ph + 36, "center", "alphabetic", font(12), COL.ink);
      g.save(); g.translate(m.l - 48, m.t + ph / 2); g.rotate(-Math.PI / 2);
      text(g, "y [m]", 0, 0, "center", "middle", font(12), COL.ink); g.restore();
    };
  }
  function drawAxes3d(g, pr) {
    const [xl, yl, zl] = LO, [xh, yh, zh] = HI, off = 0.07 * S;
    const tx = ticks(xl, xh, 5), ty = ticks(yl, yh, 5), tz = ticks(zl, zh, 4);
    const line = (a, b) => seg(g, pr.f(...a), pr.f(...b));
    g.lineWidth = 1; g.strokeStyle = COL.grid;
    for (const x of tx.values) line([x, yl, zl], [x, yh, zl]);
    for (const y of ty.values) line([xl, y, zl], [xh, y, zl]);
    g.strokeStyle = COL.frame;
    for (const [a, b] of [[[xl, yl], [xh, yl]], [[xh, yl], [xh, yh]], [[xh, yh], [xl, yh]], [[xl, yh], [xl, yl]]]) {
      line([...a, zl], [...b, zl]);
    }
    const yF = pr.f(C[0], yl, zl)[2] > pr.f(C[0], yh, zl)[2] ? yl : yh, sy = yF === yl ? -1 : 1;
    const xF = pr.f(xl, C[1], zl)[2] > pr.f(xh, C[1], zl)[2] ? xl : xh, sx = xF === xl ? -1 : 1;
    const yB = yF === yl ? yh : yl, xB = xF === xl ? xh : xl; // the back walls, as matplotlib's panes
    g.strokeStyle = COL.grid;
    for (const z of tz.values) { line([xl, yB, z], [xh, yB, z]); line([xB, yl, z], [xB, yh, z]); }
    for (const x of tx.values) line([x, yB, zl], [x, yB, zh]);
    for (const y of ty.values) line([xB, y, zl], [xB, y, zh]);
    g.strokeStyle = "#d2d2d2";
    line([xl, yB, zh], [xh, yB, zh]); line([xB, yl, zh], [xB, yh, zh]);
    for (const [x, y] of [[xl, yB], [xh, yB], [xB, yF]]) line([x, y, zl], [x, y, zh]);
    for (const x of tx.values) {
      const q = pr.f(x, yF + sy * off, zl); text(g, tx.label(x), q[0], q[1], "center", "middle", font(11), COL.axis);
    }
    for (const y of ty.values) {
      const q = pr.f(xF + sx * off, y, zl); text(g, ty.label(y), q[0], q[1], "center", "middle", font(11), COL.axis);
    }
    let q = pr.f(C[0], yF + sy * 2.6 * off, zl); text(g, "x [m]", q[0], q[1], "center", "middle", font(12), COL.ink);
    q = pr.f(xF + sx * 2.6 * off, C[1], zl); text(g, "y [m]", q[0], q[1], "center", "middle", font(12), COL.ink);
    let corner = null; // the z ruler stands on the floor corner leftmost on screen
    for (const x of [xl, xh]) for (const y of [yl, yh]) {
      const c = pr.f(x, y, zl); if (!corner || c[0] < corner.sx) corner = { x, y, sx: c[0] };
    }
    g.strokeStyle = COL.frame; line([corner.x, corner.y, zl], [corner.x, corner.y, zh]);
    for (const z of tz.values) {
      const a = pr.f(corner.x, corner.y, z);
      seg(g, [a[0] - 4, a[1]], [a[0], a[1]]);
      text(g, tz.label(z), a[0] - 7, a[1], "right", "middle", font(11), COL.axis);
    }
    q = pr.f(corner.x, corner.y, zh); text(g, "z [m]", q[0], q[1] - 12, "center", "alphabetic", font(12), COL.ink);
  }
  function drawFence(g, pr) {
    if (!D.fence) return;
    const open = dim === 2 ? 50 * S : 0; // 2-D: open sides run out of the (clipped) plot
    const lo = D.fence.min_m.map((v, a) => (v === null ? LO[a] - open : v));
    const hi = D.fence.max_m.map((v, a) => (v === null ? HI[a] + open : v));
    g.save(); g.setLineDash([7, 5]); g.strokeStyle = COL.fence; g.lineWidth = 1.4;
    for (let a = 0; a < dim; a++) {
      for (const side of [D.fence.min_m[a], D.fence.max_m[a]]) {
        if (side === null) continue;
        const others = [0, 1, 2].slice(0, dim).filter((b) => b !== a);
        const corners = dim === 2 ? [[lo[others[0]]], [hi[others[0]]]]
          : [[lo[others[0]], lo[others[1]]], [hi[others[0]], lo[others[1]]], [hi[others[0]], hi[others[1]]], [lo[others[0]], hi[others[1]]]];
        const pts = corners.map((c) => { const p = new Array(dim); p[a] = side; others.forEach((b, j) => { p[b] = c[j]; }); return pr.f(...p); });
        g.beginPath(); pts.forEach((p, j) => (j ? g.lineTo(p[0], p[1]) : g.moveTo(p[0], p[1])));
        if (dim === 3) g.closePath();
        g.stroke();
      }
    }
    g.restore();
  }
  function drawPaths(g, pr, k, time) {
    if (show.paths) {
      g.strokeStyle = "rgba(0,0,0,0.13)"; g.lineWidth = 1;
      for (let i = 0; i < n; i++) {
        g.beginPath();
        for (let j = 0; j < T; j++) { const q = pr.f(...at(P.subarray(j * stride), i)); j ? g.lineTo(q[0], q[1]) : g.moveTo(q[0], q[1]); }
        g.stroke();
      }
    }
    if (show.trails) {
      const j0 = sampleAt(Math.max(t0, time - TRAIL_S));
      g.lineWidth = 1.8; g.lineJoin = "round";
      for (let i = 0; i < n; i++) {
        g.strokeStyle = TRAIL[i % TRAIL.length]; g.globalAlpha = 0.85; g.beginPath();
        for (let j = j0; j <= k; j++) { const q = pr.f(...at(P.subarray(j * stride), i)); j > j0 ? g.lineTo(q[0], q[1]) : g.moveTo(q[0], q[1]); }
        const q = pr.f(...at(pos, i)); g.lineTo(q[0], q[1]); g.stroke();
      }
      g.globalAlpha = 1;
    }
  }
  function drawFlown(g, pr, time) { // each drone's true path so far: dotted, in its trail colour
    let m = 0; while (m < fts.length - 1 && fts[m + 1] <= time) m++;
    g.save(); g.setLineDash([2, 3]); g.lineWidth = 1.3; g.globalAlpha = 0.8;
    for (let i = 0; i < n; i++) {
      g.strokeStyle = TRAIL[i % TRAIL.length]; g.beginPath();
      for (let j = 0; j <= m; j++) { const q = pr.f(...at(F.subarray(j * stride), i)); j ? g.lineTo(q[0], q[1]) : g.moveTo(q[0], q[1]); }
      g.stroke();
    }
    g.restore();
    return m + 1;
  }
  function sphere(g, q, rp, clearPx) {
    const grad = g.createRadialGradient(q[0] - 0.35 * rp, q[1] - 0.4 * rp, 0.05 * rp, q[0], q[1], rp);
    grad.addColorStop(0, dim === 3 ? "rgba(238,240,243,0.9)" : "rgba(190,195,201,0.75)");
    grad.addColorStop(1, dim === 3 ? "rgba(128,135,145,0.85)" : "rgba(160,166,174,0.75)");
    circle(g, q[0], q[1], rp); g.fillStyle = grad; g.fill();
    g.strokeStyle = "#5f6368"; g.lineWidth = 0.9; g.stroke();
    if (clearPx > rp) {
      g.save(); g.setLineDash([4, 4]); g.strokeStyle = "#80868b"; g.lineWidth = 1;
      circle(g, q[0], q[1], clearPx); g.stroke(); g.restore();
    }
  }
  function polygon(g, pts) {
    g.beginPath(); g.moveTo(pts[0][0], pts[0][1]);
    for (let i = 1; i < pts.length; i++) g.lineTo(pts[i][0], pts[i][1]);
    g.closePath();
  }
  function outlined(g, body, grown) { // a planar obstacle: its outline, its clearance dashed
    polygon(g, body); g.fillStyle = "rgba(160,166,174,0.75)"; g.fill();
    g.strokeStyle = "#5f6368"; g.lineWidth = 0.9; g.stroke();
    g.save(); g.setLineDash([4, 4]); g.strokeStyle = "#80868b"; g.lineWidth = 1;
    polygon(g, grown); g.stroke(); g.restore();
  }
  function area2(pts) { // a screen polygon's area
    let a = 0;
    for (let i = 0; i < pts.length; i++) { const p = pts[i], q = pts[(i + 1) % pts.length]; a += p[0] * q[1] - q[0] * p[1]; }
    return Math.abs(a) / 2;
  }
  function areaOf(pts) { // a planar polygon's area in space (Newell's normal)
    const nrm = [0, 0, 0];
    for (let i = 0; i < pts.length; i++) {
      const p = pts[i], q = pts[(i + 1) % pts.length];
      nrm[0] += (p[1] - q[1]) * (p[2] + q[2]); nrm[1] += (p[2] - q[2]) * (p[0] + q[0]); nrm[2] += (p[0] - q[0]) * (p[1] + q[1]);
    }
    return Math.hypot(...nrm) / 2;
  }
  function facet(g, pts, light) { // one face of a spatial obstacle: the more it faces the screen, the lighter
    const c = Math.round(140 + 95 * light);
    polygon(g, pts); g.fillStyle = "rgba(" + c + "," + (c + 3) + "," + (c + 8) + ",0.85)"; g.fill();
    g.strokeStyle = "rgba(95,99,104,0.5)"; g.lineWidth = 0.6; g.stroke();
  }
  function drawScene(g, w, h, time) {
    const k = nearest(time), pr = projector(w, h);
    interpolate(P, time, pos); if (R) interpolate(R, time, ref);
    const below = D.below[String(k)] || [], bad = new Set(below);
    let finish = null;
    if (dim === 2) {
      finish = drawAxes2d(g, pr);
      g.save(); g.beginPath(); g.rect(pr.m.l, pr.m.t, pr.pw, pr.ph); g.clip();
    } else drawAxes3d(g, pr);
    drawFence(g, pr);
    drawPaths(g, pr, sampleAt(time), time);
    const flown = F && show.flown ? drawFlown(g, pr, time) : 0;
    if (D.wind) { // the mean wind's direction on the screen, for the legend's arrow
      const c = LO.map((l, a) => (l + HI[a]) / 2), a0 = pr.f(...c), a1 = pr.f(...c.map((v, a) => v + D.wind.mean_mps[a] * S));
      const dx = a1[0] - a0[0], dy = a1[1] - a0[1], len = Math.hypot(dx, dy);
      windDir = len > 1e-6 ? [dx / len, dy / len] : null;
    }
    const q = []; for (let i = 0; i < n; i++) q.push(pr.f(...at(pos, i)));
    const items = []; // painter's algorithm: far first
    for (const ob of D.obstacles) {
      if (ob.c) {
        const c = pr.f(...ob.c), rp = pr.s * c[3] * ob.r, cp = pr.s * c[3] * (ob.r + ob.clear);
        items.push([c[2], () => sphere(g, c, rp, cp)]);
      } else if (ob.outline) {
        items.push([-Infinity, () => outlined(g, ob.outline.map((q) => pr.f(...q)), ob.grown.map((q) => pr.f(...q)))]);
      } else {
        const v = ob.mesh.v.map((q) => pr.f(...q));
        for (const face of ob.mesh.f) {
          const pts = face.map((i) => v[i]), depth = pts.reduce((a, q) => a + q[2], 0) / pts.length;
          const px = pr.s * pts.reduce((a, q) => a + q[3], 0) / pts.length; // pixels per metre there
          const share = area2(pts) / Math.max(1e-12, px * px * areaOf(face.map((i) => ob.mesh.v[i])));
          items.push([depth, () => facet(g, pts, Math.min(1, share))]);
        }
      }
    }
    for (const [a, b] of D.edges) {
      items.push([(q[a][2] + q[b][2]) / 2 - 1e-6, () => { g.strokeStyle = COL.edge; g.lineWidth = 1.3; seg(g, q[a], q[b]); }]);
    }
    if (R && show.ref) {
      for (let i = 0; i < n; i++) {
        const c = pr.f(...at(ref, i));
        items.push([c[2], () => { circle(g, c[0], c[1], droneR * c[3] + 2); g.strokeStyle = COL.ref; g.lineWidth = 1.1; g.stroke(); }]);
      }
    }
    const depth = (z) => Math.min(1, Math.max(0, 0.5 - z / (2 * RAD)));
    for (let i = 0; i < n; i++) {
      items.push([q[i][2], () => {
        circle(g, q[i][0], q[i][1], droneR * q[i][3]);
        g.fillStyle = bad.has(i) ? COL.bad : dim === 3 && depth(q[i][2]) > 0.6 ? COL.far : COL.drone;
        g.fill(); g.strokeStyle = bad.has(i) ? "#7f0000" : COL.droneEdge; g.lineWidth = 1; g.stroke();
      }]);
    }
    items.sort((u, v) => u[0] - v[0]).forEach((it) => it[1]());
    g.strokeStyle = COL.bad; g.lineWidth = 2.6;
    for (let j = 0; j < below.length; j += 2) seg(g, q[below[j]], q[below[j + 1]]);
    for (const i of bad) { circle(g, q[i][0], q[i][1], droneR * q[i][3] + 4); g.lineWidth = 2; g.stroke(); }
    const C = D.closest; // the run's closest pair, at its sample: marked whether or not it is below d_min
    if (C && k === C.k) { g.save(); g.setLineDash([5, 3]); g.strokeStyle = COL.closest; g.lineWidth = 2; seg(g, q[C.pair[0]], q[C.pair[1]]); g.restore(); }
    if (show.ids) for (let i = 0; i < n; i++) text(g, String(i), q[i][0] + droneR * q[i][3] + 2, q[i][1] - droneR * q[i][3], "left", "alphabetic", font(10), "#333");
    if (finish) { g.restore(); finish(); }
    return { k, below: below.length / 2, flown };
  }
  let windDir = null; // set by drawScene
  function arrow(g, x, y, u) {
    const a = [x + 9 - 8 * u[0], y - 8 * u[1]], b = [x + 9 + 8 * u[0], y + 8 * u[1]];
    g.strokeStyle = g.fillStyle = COL.wind; g.lineWidth = 2; seg(g, a, b);
    g.beginPath(); g.moveTo(b[0], b[1]);
    g.lineTo(b[0] - 6 * u[0] + 3.5 * u[1], b[1] - 6 * u[1] - 3.5 * u[0]); g.lineTo(b[0] - 6 * u[0] - 3.5 * u[1], b[1] - 6 * u[1] + 3.5 * u[0]);
    g.closePath(); g.fill();
  }
  function drawLegend(g) {
    const rows = [["drone", (x, y) => { circle(g, x + 9, y, droneR); g.fillStyle = COL.drone; g.fill(); g.strokeStyle = COL.droneEdge; g.lineWidth = 1; g.stroke(); }]];
    if (R && show.ref) rows.push(["reference p*ᵢ", (x, y) => { circle(g, x + 9, y, droneR + 2); g.strokeStyle = COL.ref; g.lineWidth = 1.1; g.stroke(); }]);
    if (D.edges.length) rows.push(["formation edge", (x, y) => { g.strokeStyle = COL.edge; g.lineWidth = 1.3; seg(g, [x, y], [x + 18, y]); }]);
    if (show.trails) rows.push(["last " + TRAIL_S + " s of path (a colour per drone)", (x, y) => { g.lineWidth = 1.8; for (let c = 0; c < 3; c++) { g.strokeStyle = TRAIL[c]; seg(g, [x + 6 * c, y], [x + 6 * c + 6, y]); } }]);
    if (F && show.flown) rows.push(["flown path (the plant's true motion)", (x, y) => { g.save(); g.setLineDash([2, 3]); g.lineWidth = 1.3; g.strokeStyle = TRAIL[0]; seg(g, [x, y], [x + 18, y]); g.restore(); }]);
    if (D.d_min_m !== null) rows.push(["pair closer than d_min", (x, y) => { g.strokeStyle = COL.bad; g.lineWidth = 2.6; seg(g, [x, y], [x + 18, y]); }]);
    if (D.obstacles.length) rows.push(["obstacle (dashed: + clearance)", (x, y) => sphere(g, [x + 9, y], 6, 9)]);
    if (D.wind) {
      const w = D.wind, speed = Math.hypot(...w.mean_mps), gusts = w.gust_std_mps > 0 ? ", gusts " + fmtValue(w.gust_std_mps) + " m/s std" : "";
      rows.push(["wind " + fmtValue(speed) + " m/s" + gusts + (windDir ? "" : " (across this view)"), (x, y) => { if (windDir) arrow(g, x, y, windDir); }]);
    }
    if (D.fence) rows.push(["geofence", (x, y) => { g.save(); g.setLineDash([5, 3]); g.strokeStyle = COL.fence; g.lineWidth = 1.4; seg(g, [x, y], [x + 18, y]); g.restore(); }]);
    const x0 = dim === 2 ? 74 : 10, y0 = dim === 2 ? 24 : 10, lh = 18;
    g.font = font(12);
    const w = 34 + Math.max(...rows.map((r) => g.measureText(r[0]).width));
    g.fillStyle = "rgba(255,255,255,0.88)"; g.strokeStyle = "#d5d5d5"; g.lineWidth = 1;
    g.fillRect(x0, y0, w, rows.length * lh + 8); g.strokeRect(x0, y0, w, rows.length * lh + 8);
    rows.forEach(([label, mark], j) => { const y = y0 + 4 + lh * j + lh / 2; mark(x0 + 6, y); text(g, label, x0 + 30, y, "left", "middle", font(12), COL.ink); });
  }
  const TRIAD = [["x", "#d62728"], ["y", "#2ca02c"], ["z", "#1f77b4"]];
  let triad = null; // the 3-D triad's tips, from the scene's lower left [px], published for tests
  function drawTriad(g, h) { // the world axes' directions in the lower left, rotated with the view
    const ca = Math.cos(view.az), sa = Math.sin(view.az), ce = Math.cos(view.el), se = Math.sin(view.el);
    const o = [54, h - 58], L = 34; // the rotation of projector(), without perspective, pan or zoom
    const axes = [[-sa, -se * ca, ce * ca], [ca, -se * sa, ce * sa], [0, ce, se]].map((u, a) => ({ u, a }));
    g.fillStyle = "rgba(255,255,255,0.85)"; circle(g, o[0], o[1], L + 14); g.fill();
    triad = [];
    for (const { u, a } of axes.sort((p, q) => p.u[2] - q.u[2])) { // the farthest first
      const tip = [o[0] + L * u[0], o[1] - L * u[1]], len = Math.hypot(u[0], u[1]) || 1;
      g.strokeStyle = TRIAD[a][1]; g.lineWidth = 2.4; g.lineCap = "round"; seg(g, o, tip); g.lineCap = "butt";
      const lx = tip[0] + (9 * u[0]) / len, ly = tip[1] - (9 * u[1]) / len;
      text(g, TRIAD[a][0], lx, ly, "center", "middle", font(12, "600"), TRIAD[a][1]);
      triad[a] = [tip[0], h - tip[1]];
    }
    circle(g, o[0], o[1], 2); g.fillStyle = COL.ink; g.fill();
  }
  function renderScene() {
    const { g, w, h } = fit(canvas);
    const info = drawScene(g, w, h, state.time);
    drawLegend(g);
    if (dim === 3) drawTriad(g, h);
    const [tx, ty] = dim === 2 ? [w - 26, 40] : [w - 14, 26]; // 2-D: inside the plot's frame
    text(g, "t = " + state.time.toFixed(TIME_DEC) + " s", tx, ty, "right", "alphabetic", font(16, "600"), COL.ink);
    const hint = dim === 3 ? "drag: orbit · shift-drag: pan · wheel: zoom · double-click: reset" : "drag: pan · wheel: zoom · double-click: reset";
    text(g, hint, w - 10, h - 8, "right", "alphabetic", font(11), "#999");
    return info;
  }

  // ---- metric panels -----------------------------------------------------------------------
  const panels = D.curves.map((c) => {
    const el = document.createElement("canvas"); el.setAttribute("aria-label", c.label);
    $("panels").appendChild(el);
    const ys = c.y.filter((v) => v !== null), lim = c.limit ? c.limit.value : null;
    let lo, hi;
    if (c.log) {
      const posv = ys.filter((v) => v > 0).concat(lim && lim > 0 ? [lim] : []);
      lo = Math.pow(10, Math.floor(Math.log10(Math.min(...posv)))); hi = Math.pow(10, Math.ceil(Math.log10(Math.max(...posv))));
    } else {
      const all = ys.concat(lim !== null ? [lim] : []);
      lo = Math.min(0, ...all); hi = Math.max(...all); hi = hi + 0.12 * (hi - lo || 1);
    }
    return { c, el, lo, hi };
  });
  if (!panels.length) $("panels").style.display = "none";
  function drawPanel(p, kn, last) {
    const { g, w, h } = fit(p.el), c = p.c;
    const m = { l: 62, r: 14, t: 26, b: last ? 40 : 24 }, pw = w - m.l - m.r, ph = h - m.t - m.b;
    const X = (t) => m.l + (pw * (t - t0)) / span_t;
    const Y = c.log ? (v) => m.t + ph * (1 - Math.log10(Math.max(v, p.lo) / p.lo) / Math.log10(p.hi / p.lo))
      : (v) => m.t + ph * (1 - (v - p.lo) / (p.hi - p.lo));
    const tx = ticks(t0, t1, pw / 70);
    g.lineWidth = 1; g.strokeStyle = COL.grid;
    for (const t of tx.values) seg(g, [X(t), m.t], [X(t), m.t + ph]);
    const yt = [];
    if (c.log) for (let e = Math.round(Math.log10(p.lo)); e <= Math.round(Math.log10(p.hi)); e++) yt.push([Math.pow(10, e), "10" + sup(e)]);
    else { const ty = ticks(p.lo, p.hi, ph / 38); for (const v of ty.values) yt.push([v, ty.label(v)]); }
    const step = Math.ceil(yt.length / Math.max(2, Math.floor(ph / 22)));
    yt.forEach(([v, s], j) => {
      g.strokeStyle = COL.grid; seg(g, [m.l, Y(v)], [m.l + pw, Y(v)]);
      if (j % step === 0) text(g, s, m.l - 6, Y(v), "right", "middle", font(11), COL.axis);
    });
    for (const t of tx.values) text(g, tx.label(t), X(t), m.t + ph + 15, "center", "alphabetic", font(11), COL.axis);
    if (last) text(g, "time t [s]", m.l + pw / 2, m.t + ph + 33, "center", "alphabetic", font(12), COL.ink);
    g.save(); g.beginPath(); g.rect(m.l, m.t, pw, ph); g.clip();
    const trace = () => {
      g.beginPath(); let pen = false;
      c.y.forEach((v, j) => { if (v === null) { pen = false; return; } pen ? g.lineTo(X(ts[j]), Y(v)) : g.moveTo(X(ts[j]), Y(v)); pen = true; });
      g.stroke();
    };
    g.lineWidth = 1.6; g.strokeStyle = COL.curve; g.lineJoin = "round"; trace();
    if (c.limit) {
      const yl = Y(c.limit.value);
      g.save(); g.beginPath();
      c.limit.kind === "min" ? g.rect(m.l, yl, pw, m.t + ph - yl) : g.rect(m.l, m.t, pw, yl - m.t);
      g.clip(); g.strokeStyle = COL.bad; trace(); g.restore();
      g.save(); g.setLineDash([6, 4]); g.strokeStyle = COL.bad; g.lineWidth = 1.2; seg(g, [m.l, yl], [m.l + pw, yl]); g.restore();
      text(g, c.limit.label, m.l + pw - 4, yl - 4, "right", "alphabetic", font(11), COL.bad);
    }
    g.restore();
    g.strokeStyle = COL.frame; g.strokeRect(m.l, m.t, pw, ph);
    const xc = X(state.time), v = c.y[kn];
    g.strokeStyle = COL.ink; g.lineWidth = 1; seg(g, [xc, m.t], [xc, m.t + ph]);
    if (v !== null) { circle(g, X(ts[kn]), Y(v), 3.5); g.fillStyle = COL.ink; g.fill(); }
    text(g, c.label + (c.unit ? " [" + c.unit + "]" : ""), m.l, m.t - 8, "left", "alphabetic", font(12, "600"), COL.ink);
    const viol = v !== null && c.limit && (c.limit.kind === "min" ? v < c.limit.value : v > c.limit.value);
    text(g, fmtValue(v) + (c.unit ? " " + c.unit : ""), m.l + pw, m.t - 8, "right", "alphabetic", font(12, "600"), viol ? COL.bad : COL.ink);
    p.X = X; p.m = m; p.pw = pw;
  }
  function sup(e) { return String(e).split("").map((ch) => "⁰¹²³⁴⁵⁶⁷⁸⁹"["0123456789".indexOf(ch)] || "⁻").join(""); }

  // ---- render, controls --------------------------------------------------------------------
  function render() {
    const info = renderScene(), kn = info.k;
    panels.forEach((p, j) => drawPanel(p, kn, j === panels.length - 1));
    slider.value = String(state.time);
    $("clock").textContent = "t = " + state.time.toFixed(TIME_DEC) + " s / " + t1.toFixed(TIME_DEC) + " s   sample " + (kn + 1) + "/" + T;
    const st = $("status");
    if (D.d_min_m === null) { st.textContent = ""; st.className = ""; }
    else if (info.below) { st.textContent = info.below + (info.below > 1 ? " pairs" : " pair") + " closer than d_min"; st.className = "bad"; }
    else { st.textContent = "no pair closer than d_min" + closestText(); st.className = "good"; }
    body.dataset.sample = String(kn); body.dataset.below = String(info.below); body.dataset.flown = String(info.flown);
    if (D.wind) body.dataset.wind = windDir ? windDir.map((v) => v.toFixed(2)).join(",") : "across";
    if (extent) body.dataset.extent = extent.map((v) => v.toFixed(3)).join(",");
    if (triad) body.dataset.triad = triad.map((q) => q.map((v) => v.toFixed(1)).join(",")).join(";");
    return info;
  }
  function closestText() {
    const C = D.closest;
    return C ? "; closest " + C.pair[0] + "-" + C.pair[1] + ": " + C.m + " m at t = " + D.t_s[C.k] + " s" : "";
  }
  function seek(time) { state.time = Math.min(t1, Math.max(t0, time)); render(); }
  function setPlaying(on) {
    state.playing = on && T > 1;
    playBtn.innerHTML = state.playing ? "&#10074;&#10074; Pause" : "&#9654; Play";
    if (state.playing) {
      if (state.time >= t1) state.time = t0;
      state.last = performance.now(); requestAnimationFrame(tick);
    }
  }
  function tick(now) {
    if (!state.playing) return;
    state.time = Math.min(t1, state.time + ((now - state.last) / 1000) * state.speed); state.last = now;
    render();
    if (state.time >= t1) setPlaying(false); else requestAnimationFrame(tick);
  }
  slider.min = String(t0); slider.max = String(t1); slider.disabled = T < 2;
  slider.addEventListener("input", () => { setPlaying(false); seek(parseFloat(slider.value)); });
  playBtn.addEventListener("click", () => { setPlaying(!state.playing); playBtn.blur(); });
  $("speed").addEventListener("change", (e) => { state.speed = parseFloat(e.target.value); });
  for (const key of ["paths", "trails", "ref", "flown", "ids"]) {
    const box = $("show-" + key); box.checked = show[key];
    if ((key === "ref" && !R) || (key === "flown" && !F)) box.parentElement.style.display = "none";
    box.addEventListener("change", () => { show[key] = box.checked; render(); });
  }
  $("reset").addEventListener("click", () => { Object.assign(view, HOME); render(); });
  document.addEventListener("keydown", (e) => {
    if (e.target instanceof HTMLSelectElement || (e.target instanceof HTMLInputElement && e.target.type !== "checkbox" && e.target.type !== "range")) return;
    const k = sampleAt(state.time);
    if (e.key === " ") setPlaying(!state.playing);
    else if (e.key === "ArrowRight") { setPlaying(false); seek(ts[Math.min(T - 1, k + 1)]); }
    else if (e.key === "ArrowLeft") { setPlaying(false); seek(ts[Math.max(0, ts[k] < state.time ? k : k - 1)]); }
    else if (e.key === "Home") seek(t0);
    else if (e.key === "End") seek(t1);
    else return;
    e.preventDefault();
  });
  let drag = null;
  canvas.addEventListener("pointerdown", (e) => {
    drag = { x: e.clientX, y: e.clientY, pan: dim === 2 || e.shiftKey || e.button !== 0 };
    canvas.setPointerCapture(e.pointerId);
  });
  canvas.addEventListener("pointermove", (e) => {
    if (!drag) return;
    const dx = e.clientX - drag.x, dy = e.clientY - drag.y; drag.x = e.clientX; drag.y = e.clientY;
    if (drag.pan) { view.panX += dx; view.panY += dy; }
    else { view.az -= dx * 0.01; view.el = Math.max(-1.5, Math.min(1.5, view.el + dy * 0.01)); }
    renderScene();
  });
  canvas.addEventListener("pointerup", () => { drag = null; });
  canvas.addEventListener("contextmenu", (e) => e.preventDefault());
  canvas.addEventListener("dblclick", () => { Object.assign(view, HOME); render(); });
  canvas.addEventListener("wheel", (e) => {
    e.preventDefault();
    const r = canvas.getBoundingClientRect(), pr = projector(r.width, r.height);
    const zoom = Math.max(0.1, Math.min(60, view.zoom * Math.exp(-e.deltaY * 0.0015))), q = zoom / view.zoom;
    const mx = e.clientX - r.left - pr.centre[0], my = e.clientY - r.top - pr.centre[1];
    view.panX = mx - q * (mx - view.panX); view.panY = my - q * (my - view.panY); view.zoom = zoom;
    renderScene();
  }, { passive: false });
  panels.forEach((p) => {
    const to = (e) => { const r = p.el.getBoundingClientRect(); seek(t0 + ((e.clientX - r.left - p.m.l) / p.pw) * span_t); };
    p.el.addEventListener("pointerdown", (e) => { setPlaying(false); p.drag = true; p.el.setPointerCapture(e.pointerId); to(e); });
    p.el.addEventListener("pointermove", (e) => { if (p.drag) to(e); });
    p.el.addEventListener("pointerup", () => { p.drag = false; });
  });
  window.addEventListener("resize", render);

  // ---- header, first frame, self-check -----------------------------------------------------
  const meta = [n + (n === 1 ? " drone" : " drones"), dim + "-D", T + " samples, t = " + t0 + "–" + t1 + " s"];
  if (D.d_min_m !== null) meta.push("d_min = " + D.d_min_m + " m");
  if (D.v_max_mps !== null) meta.push("v_max = " + D.v_max_mps + " m/s");
  if (D.obstacles.length) meta.push(D.obstacles.length + (D.obstacles.length === 1 ? " obstacle" : " obstacles"));
  if (D.fence) meta.push("geofence");
  $("meta").textContent = meta.join(" · ");
  if (D.events) { const ev = document.createElement("span"); ev.className = "events"; ev.textContent = " · plant: " + D.events; $("meta").appendChild(ev); }
  const hash = /(?:^#|&)t=([-0-9.eE+]+)/.exec(window.location.hash);
  const info = (state.time = hash ? Math.min(t1, Math.max(t0, parseFloat(hash[1]) || t0)) : t0, render());
  const px = canvas.getContext("2d").getImageData(0, 0, canvas.width, canvas.height).data;
  let ink = 0; for (let j = 0; j < px.length; j += 4) if (px[j] < 200 || px[j + 1] < 200 || px[j + 2] < 200) ink++;
  if (ink < 200) { body.dataset.viewer = "error:blank scene"; console.error("viewer: blank scene"); }
  else {
    body.dataset.viewer = "ok:" + T;
    console.log("viewer-ready samples=" + T + " drones=" + n + " dim=" + dim + " sample=" + info.k + " below=" + info.below);
  }
  const speed = /(?:^#|&)speed=([0-9.]+)/.exec(window.location.hash), sel = $("speed");
  if (speed && [...sel.options].some((o) => o.value === speed[1])) { sel.value = speed[1]; state.speed = parseFloat(speed[1]); }
  if (/(?:^#|&)play(?:&|$)/.test(window.location.hash)) setPlaying(true);
})();
