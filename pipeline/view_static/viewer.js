// hollowtree view: a small WebGL point viewer for a labelled run store (no libraries, no network
// beyond this page's own server). Nodes (a tile's chunk) arrive level by level (view_lod.py).
"use strict";
(function () {
  const $ = (id) => document.getElementById(id);
  const canvas = $("view");
  const gl = canvas.getContext("webgl", { antialias: false, preserveDrawingBuffer: true });
  const V = (window.hollowtreeViewer = { ready: false, errors: [], batches: [], loaded: 0, requests: 0 });
  const BG = [0.082, 0.09, 0.106];
  const POINT_BUDGET = 4000000, CONCURRENCY = 3;
  let meta = null, mode = "class", pointSize = 4, dirty = true;
  const mask = new Float32Array(16).fill(1);
  const highlight = { on: false, test: null };
  const nodes = new Map(); // "t/c" -> {tile, chunk, rows, level (highest loaded), pending, box}

  // ------------------------------------------------------------------ small maths
  function perspective(fovy, aspect, near, far) {
    const f = 1 / Math.tan(fovy / 2), nf = 1 / (near - far);
    return [f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) * nf, -1, 0, 0, 2 * far * near * nf, 0];
  }
  function lookAt(e, c, up) {
    let zx = e[0] - c[0], zy = e[1] - c[1], zz = e[2] - c[2];
    let l = Math.hypot(zx, zy, zz); zx /= l; zy /= l; zz /= l;
    let xx = up[1] * zz - up[2] * zy, xy = up[2] * zx - up[0] * zz, xz = up[0] * zy - up[1] * zx;
    l = Math.hypot(xx, xy, xz) || 1; xx /= l; xy /= l; xz /= l;
    const yx = zy * xz - zz * xy, yy = zz * xx - zx * xz, yz = zx * xy - zy * xx;
    return [xx, yx, zx, 0, xy, yy, zy, 0, xz, yz, zz, 0,
      -(xx * e[0] + xy * e[1] + xz * e[2]), -(yx * e[0] + yy * e[1] + yz * e[2]), -(zx * e[0] + zy * e[1] + zz * e[2]), 1];
  }
  function mul(a, b) { // column-major a * b
    const o = new Array(16);
    for (let c = 0; c < 4; c++) for (let r = 0; r < 4; r++) {
      let s = 0; for (let k = 0; k < 4; k++) s += a[k * 4 + r] * b[c * 4 + k]; o[c * 4 + r] = s;
    }
    return o;
  }

  // ------------------------------------------------------------------ camera
  const cam = { target: [0, 0, 0], dist: 100, yaw: -0.6, pitch: 0.6, fov: 0.8 };
  function eye() {
    const cp = Math.cos(cam.pitch);
    return [cam.target[0] + cam.dist * cp * Math.cos(cam.yaw), cam.target[1] + cam.dist * cp * Math.sin(cam.yaw),
      cam.target[2] + cam.dist * Math.sin(cam.pitch)];
  }
  function mvp() {
    const w = canvas.width, h = canvas.height;
    return mul(perspective(cam.fov, w / Math.max(h, 1), cam.dist / 200, cam.dist * 20), lookAt(eye(), cam.target, [0, 0, 1]));
  }
  function fit(box) {
    cam.target = [(box[0] + box[3]) / 2, (box[1] + box[4]) / 2, (box[2] + box[5]) / 2];
    const r = Math.hypot(box[3] - box[0], box[4] - box[1]) / 2;
    cam.dist = Math.max(r / Math.tan(cam.fov / 2) * 0.5, 1);
    dirty = true;
  }

  // ------------------------------------------------------------------ GL
  const VS = `attribute vec3 p; attribute vec3 col; attribute float cls; attribute float hl; attribute float sp;
    uniform mat4 m; uniform float size; uniform float proj; uniform float mask[16]; uniform float hlOn; varying vec3 c;
    void main() {
      float on = mask[int(cls + 0.5)];
      if (on < 0.5) { gl_Position = vec4(2.0, 2.0, 2.0, 1.0); gl_PointSize = 0.0; return; }
      gl_Position = m * vec4(p, 1.0);
      // at least size pixels, and as large as the node's point spacing on screen (no holes)
      float px = clamp(max(size, size / 4.0 * 1.2 * sp * proj / max(gl_Position.w, 1e-6)), 1.0, 3.0 * size);
      gl_PointSize = px * (hl > 0.5 && hlOn > 0.5 ? 1.6 : 1.0);
      c = (hlOn > 0.5 && hl < 0.5) ? col * 0.28 : (hl > 0.5 && hlOn > 0.5 ? mix(col, vec3(1.0, 0.9, 0.2), 0.35) : col);
    }`;
  const FS = `precision mediump float; varying vec3 c; void main() { gl_FragColor = vec4(c, 1.0); }`;
  function shader(type, src) {
    const s = gl.createShader(type); gl.shaderSource(s, src); gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
    return s;
  }
  const prog = gl.createProgram();
  gl.attachShader(prog, shader(gl.VERTEX_SHADER, VS)); gl.attachShader(prog, shader(gl.FRAGMENT_SHADER, FS));
  gl.linkProgram(prog);
  if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(prog));
  const loc = { p: gl.getAttribLocation(prog, "p"), col: gl.getAttribLocation(prog, "col"), cls: gl.getAttribLocation(prog, "cls"),
    hl: gl.getAttribLocation(prog, "hl"), m: gl.getUniformLocation(prog, "m"), size: gl.getUniformLocation(prog, "size"),
    mask: gl.getUniformLocation(prog, "mask"), hlOn: gl.getUniformLocation(prog, "hlOn"),
    sp: gl.getAttribLocation(prog, "sp"), proj: gl.getUniformLocation(prog, "proj") };

  function buffer(data) { const b = gl.createBuffer(); gl.bindBuffer(gl.ARRAY_BUFFER, b); gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW); return b; }

  function draw() {
    dirty = false;
    const dpr = window.devicePixelRatio || 1;
    const w = Math.round(canvas.clientWidth * dpr), h = Math.round(canvas.clientHeight * dpr);
    if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
    gl.viewport(0, 0, w, h);
    gl.clearColor(BG[0], BG[1], BG[2], 1); gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.enable(gl.DEPTH_TEST);
    gl.useProgram(prog);
    gl.uniformMatrix4fv(loc.m, false, new Float32Array(mvp()));
    gl.uniform1f(loc.size, pointSize * dpr);
    gl.uniform1fv(loc.mask, mask);
    gl.uniform1f(loc.hlOn, highlight.on ? 1 : 0);
    gl.uniform1f(loc.proj, h / (2 * Math.tan(cam.fov / 2)));
    for (const b of V.batches) {
      gl.bindBuffer(gl.ARRAY_BUFFER, b.gp); gl.enableVertexAttribArray(loc.p); gl.vertexAttribPointer(loc.p, 3, gl.FLOAT, false, 0, 0);
      gl.bindBuffer(gl.ARRAY_BUFFER, b.gc); gl.enableVertexAttribArray(loc.col); gl.vertexAttribPointer(loc.col, 3, gl.UNSIGNED_BYTE, true, 0, 0);
      gl.bindBuffer(gl.ARRAY_BUFFER, b.gk); gl.enableVertexAttribArray(loc.cls); gl.vertexAttribPointer(loc.cls, 1, gl.UNSIGNED_BYTE, false, 0, 0);
      gl.bindBuffer(gl.ARRAY_BUFFER, b.gh); gl.enableVertexAttribArray(loc.hl); gl.vertexAttribPointer(loc.hl, 1, gl.UNSIGNED_BYTE, false, 0, 0);
      gl.bindBuffer(gl.ARRAY_BUFFER, b.gs); gl.enableVertexAttribArray(loc.sp); gl.vertexAttribPointer(loc.sp, 1, gl.FLOAT, false, 0, 0);
      gl.drawArrays(gl.POINTS, 0, b.n);
    }
    status();
  }
  // nothing is drawn before the first view is in (a count says how far it is): software WebGL
  // would take the CPU that the server needs; on a slow store (S3) a draw every 2 s shows progress
  let lastDraw = 0;
  function loop(t) {
    if (dirty && (V.ready || t - lastDraw > 2000)) { draw(); lastDraw = t; } else if (!V.ready) status();
    requestAnimationFrame(loop);
  }

  // ------------------------------------------------------------------ colours
  function hash(v) { v = Math.imul(v ^ (v >>> 16), 0x45d9f3b); v = Math.imul(v ^ (v >>> 16), 0x45d9f3b); return (v ^ (v >>> 16)) >>> 0; }
  function ramp(t) { // dark blue - teal - yellow
    t = Math.min(1, Math.max(0, t));
    return [Math.round(255 * Math.min(1, Math.max(0, 1.6 * t - 0.5))), Math.round(255 * (0.15 + 0.75 * t)), Math.round(255 * (0.55 - 0.45 * t))];
  }
  function colours(b) {
    const n = b.n, out = new Uint8Array(n * 3), cl = meta.classes;
    for (let i = 0; i < n; i++) {
      let r, g, bl;
      if (mode === "instance" || mode === "segment") {
        const id = mode === "instance" ? b.instance[i] : b.segment[i];
        if (id === 0) { r = g = bl = 70; } else { const h = hash(id); r = 60 + (h & 127); g = 60 + ((h >>> 8) & 127); bl = 60 + ((h >>> 16) & 127); }
      } else if (mode === "score") { [r, g, bl] = ramp(b.score[i]); }
      else if (mode === "rgb" && b.rgb) { r = b.rgb[3 * i]; g = b.rgb[3 * i + 1]; bl = b.rgb[3 * i + 2]; }
      else if (mode === "intensity" && b.intensity) { const v = Math.min(255, Math.round(255 * b.intensity[i] / V.intensityMax)); r = g = bl = v; }
      else { const c = (cl[b.cls[i]] || cl[0]).colour; r = c[0]; g = c[1]; bl = c[2]; }
      out[3 * i] = r; out[3 * i + 1] = g; out[3 * i + 2] = bl;
    }
    return out;
  }
  function recolour() {
    for (const b of V.batches) { gl.bindBuffer(gl.ARRAY_BUFFER, b.gc); gl.bufferData(gl.ARRAY_BUFFER, colours(b), gl.STATIC_DRAW); }
    dirty = true;
  }
  function rehighlight(b) {
    const h = new Uint8Array(b.n);
    if (highlight.on) for (let i = 0; i < b.n; i++) h[i] = highlight.test(b, i) ? 1 : 0;
    gl.bindBuffer(gl.ARRAY_BUFFER, b.gh); gl.bufferData(gl.ARRAY_BUFFER, h, gl.STATIC_DRAW);
  }
  function setHighlight(test) {
    highlight.on = !!test; highlight.test = test;
    for (const b of V.batches) rehighlight(b);
    dirty = true;
  }

  // ------------------------------------------------------------------ loading
  function parse(buf) {
    const hl = new DataView(buf).getUint32(0, true);
    const head = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 4, hl)));
    const base = 4 + hl, T = { f4: Float32Array, u1: Uint8Array, u2: Uint16Array, u4: Uint32Array };
    const a = {};
    for (const f of head.fields) a[f.name] = new T[f.dtype](buf, base + f.offset, f.shape.reduce((x, y) => x * y, 1));
    return [head, a];
  }
  function addBatch(head, a) {
    const b = { tile: head.tile, chunk: head.chunk, level: head.level, first: head.first, n: head.n, pos: a.position, cls: a["class"],
      instance: a.instance, segment: a.segment, leaf: a.leaf, score: a.score, rgb: a.rgb, intensity: a.intensity };
    if (b.intensity) { let m = V.intensityMax || 1; for (let i = 0; i < b.n; i += 7) if (b.intensity[i] > m) m = b.intensity[i]; V.intensityMax = m; }
    b.gp = buffer(b.pos); b.gc = buffer(colours(b)); b.gk = buffer(b.cls); b.gh = buffer(new Uint8Array(b.n));
    if (highlight.on) rehighlight(b);
    const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    for (let i = 0; i < b.n; i++) for (let k = 0; k < 3; k++) { const v = b.pos[3 * i + k]; if (v < lo[k]) lo[k] = v; if (v > hi[k]) hi[k] = v; }
    const nd = nodes.get(head.tile + "/" + head.chunk);
    if (b.n) nd.box = nd.box ? [Math.min(nd.box[0], lo[0]), Math.min(nd.box[1], lo[1]), Math.min(nd.box[2], lo[2]),
      Math.max(nd.box[3], hi[0]), Math.max(nd.box[4], hi[1]), Math.max(nd.box[5], hi[2])] : [...lo, ...hi];
    nd.loaded = (nd.loaded || 0) + b.n; b.node = nd; b.gs = gl.createBuffer();
    V.batches.push(b); V.loaded += b.n; dirty = true;
    spacing(nd);
  }
  // each point's spacing (metres) from the points of its node in the same 3-D cell, so that
  // sparse parts of a scan (far ground between scan lines) are drawn without holes
  function spacing(nd) {
    const bs = V.batches.filter((b) => b.node === nd), box = nd.box;
    if (!box || !nd.loaded) return;
    const c = 3 * Math.sqrt(Math.max((box[3] - box[0]) * (box[4] - box[1]), 1e-6) / nd.loaded);
    let size = 1; while (size < 2 * nd.loaded) size *= 2;
    const counts = new Uint32Array(size), mask = size - 1;
    const key = (p, i) => (Math.imul(Math.floor((p[3 * i] - box[0]) / c), 73856093) ^ Math.imul(Math.floor((p[3 * i + 1] - box[1]) / c), 19349663)
      ^ Math.imul(Math.floor((p[3 * i + 2] - box[2]) / c), 83492791)) & mask;
    for (const b of bs) for (let i = 0; i < b.n; i++) counts[key(b.pos, i)]++;
    for (const b of bs) {
      const s = new Float32Array(b.n);
      for (let i = 0; i < b.n; i++) s[i] = c / Math.sqrt(counts[key(b.pos, i)]);
      b.sp = s;
      gl.bindBuffer(gl.ARRAY_BUFFER, b.gs); gl.bufferData(gl.ARRAY_BUFFER, s, gl.STATIC_DRAW);
    }
  }
  async function fetchNode(nd, level) {
    const first = nd.level + 1;
    nd.pending = true; V.requests++;
    try {
      const r = await fetch(`/api/node?tile=${nd.tile}&chunk=${nd.chunk}&first=${first}&level=${level}`);
      if (!r.ok) throw new Error(`node ${nd.tile}/${nd.chunk}: HTTP ${r.status}`);
      const [head, a] = parse(await r.arrayBuffer());
      nd.level = level; addBatch(head, a);
    } finally { nd.pending = false; }
  }
  async function pool(jobs) {
    let i = 0;
    const worker = async () => { while (i < jobs.length) { const j = jobs[i++]; await j(); } };
    await Promise.all(Array.from({ length: Math.min(CONCURRENCY, jobs.length) }, worker));
  }
  // how many levels a node wants: about one point per 6 screen pixels of its box
  function wanted(nd) {
    if (!nd.box) return 0;
    const m = mvp(), b = nd.box, w = canvas.width, h = canvas.height;
    let x0 = Infinity, y0 = Infinity, x1 = -Infinity, y1 = -Infinity, front = false;
    for (let k = 0; k < 8; k++) {
      const x = b[(k & 1) ? 3 : 0], y = b[(k & 2) ? 4 : 1], z = b[(k & 4) ? 5 : 2];
      const cw = m[3] * x + m[7] * y + m[11] * z + m[15];
      if (cw <= 0) { front = true; continue; }
      const sx = (m[0] * x + m[4] * y + m[8] * z + m[12]) / cw, sy = (m[1] * x + m[5] * y + m[9] * z + m[13]) / cw;
      x0 = Math.min(x0, sx); x1 = Math.max(x1, sx); y0 = Math.min(y0, sy); y1 = Math.max(y1, sy);
    }
    if (!front && (x1 < -1 || x0 > 1 || y1 < -1 || y0 > 1)) return -1; // out of view
    const area = front ? w * h : Math.max(0, (Math.min(x1, 1) - Math.max(x0, -1)) * (Math.min(y1, 1) - Math.max(y0, -1)) * w * h / 4);
    const want = area / 6, l0 = nd.rows / 64;
    return Math.max(0, Math.min(meta.levels - 1, Math.ceil(Math.log2(Math.max(want / l0, 1)))));
  }
  // free at least `need` points: the top levels of the nodes holding more than they now
  // want (those out of view first); level 0 stays everywhere
  function evict(need) {
    const cands = [];
    for (const nd of nodes.values()) {
      if (nd.pending || nd.level <= 0) continue;
      const w = Math.max(wanted(nd), 0);
      if (nd.level > w) cands.push([wanted(nd) < 0 ? 1e9 : nd.level - w, nd, w]);
    }
    cands.sort((a, b) => b[0] - a[0]);
    let freed = 0;
    for (const [, nd, w] of cands) {
      let changed = false;
      while (nd.level > w && freed < need) {
        let top = null;
        for (const b of V.batches) if (b.node === nd && (!top || b.level > top.level)) top = b;
        if (!top || top.first === 0) break;
        V.batches.splice(V.batches.indexOf(top), 1);
        for (const k of ["gp", "gc", "gk", "gh", "gs"]) gl.deleteBuffer(top[k]);
        V.loaded -= top.n; nd.loaded -= top.n; nd.level = top.first - 1; freed += top.n; changed = true;
      }
      if (changed) spacing(nd);
      if (freed >= need) break;
    }
    dirty = true;
    return freed;
  }
  let refining = false, refineAgain = false;
  async function refine() {
    if (!V.ready) return;
    if (refining) { refineAgain = true; return; }
    refining = true;
    try {
      do {
        refineAgain = false;
        const todo = [];
        for (const nd of nodes.values()) {
          if (nd.pending) continue;
          if (nd.level < 0) { todo.push([1e12, nd, 0]); continue; } // never seen: its level 0 first
          const w = wanted(nd);
          if (w > nd.level) todo.push([(w - nd.level) * nd.rows, nd, Math.min(w, nd.level + 2)]);
        }
        todo.sort((a, b) => b[0] - a[0]);
        const jobs = [], top = todo.slice(0, 12);
        const adds = top.map(([, nd, level]) => Math.ceil(nd.rows * Math.pow(2, level - meta.levels + 1)) -
          (nd.level < 0 ? 0 : Math.ceil(nd.rows * Math.pow(2, nd.level - meta.levels + 1))));
        const sum = adds.reduce((a, b) => a + b, 0);
        if (sum > POINT_BUDGET - V.loaded) evict(sum - (POINT_BUDGET - V.loaded));
        let budget = POINT_BUDGET - V.loaded;
        for (const [k, [, nd, level]] of top.entries()) {
          const add = adds[k];
          if (add > budget) continue;
          budget -= add; jobs.push(() => fetchNode(nd, level));
        }
        if (!jobs.length) break;
        await pool(jobs);
      } while (true);
    } catch (e) { V.errors.push(String(e)); console.warn(e); }
    refining = false;
  }
  let refineTimer = 0;
  function moved() { dirty = true; clearTimeout(refineTimer); refineTimer = setTimeout(refine, 250); }

  // ------------------------------------------------------------------ counts, legend, status
  V.drawnCount = () => { let n = 0; for (const b of V.batches) for (let i = 0; i < b.n; i++) if (mask[b.cls[i]] > 0.5) n++; return n; };
  V.loadedCount = () => V.loaded;
  V.highlightedCount = () => { let n = 0; if (highlight.on) for (const b of V.batches) for (let i = 0; i < b.n; i++) if (highlight.test(b, i)) n++; return n; };
  V.busy = () => refining || [...nodes.values()].some((n) => n.pending);
  function status() {
    $("status").textContent = `${V.loaded.toLocaleString()} points loaded` + (V.ready ? "" : " (loading)");
  }
  function legend() {
    const tb = $("legend").querySelector("tbody");
    tb.innerHTML = "";
    for (const c of meta.classes) {
      if (!c.count) continue;
      const tr = document.createElement("tr");
      tr.dataset.cls = c.id; tr.dataset.count = c.count;
      tr.innerHTML = `<td><input type="checkbox" checked data-cls="${c.id}"></td>` +
        `<td><span class="swatch" style="background:rgb(${c.colour.join(",")})"></span>${c.name}</td><td class="n">${c.count.toLocaleString("en-US")}</td>`;
      tb.appendChild(tr);
    }
    tb.addEventListener("change", (e) => { const id = +e.target.dataset.cls; V.setClassVisible(id, e.target.checked); });
    $("stats").textContent = `${meta.n_input.toLocaleString("en-US")} input points, ${Object.keys(meta.tiles).length} tiles, ${meta.nodes.length} nodes`;
  }
  V.setClassVisible = (id, on) => {
    mask[id] = on ? 1 : 0; dirty = true;
    const box = document.querySelector(`#legend input[data-cls="${id}"]`); if (box) box.checked = on;
  };

  // ------------------------------------------------------------------ picking
  V.project = (x, y, z) => { // world coordinates -> page (client) pixels
    const o = meta.origin, p = [x - o[0], y - o[1], z - o[2]], m = mvp(), r = canvas.getBoundingClientRect();
    const cw = m[3] * p[0] + m[7] * p[1] + m[11] * p[2] + m[15];
    const sx = (m[0] * p[0] + m[4] * p[1] + m[8] * p[2] + m[12]) / cw, sy = (m[1] * p[0] + m[5] * p[1] + m[9] * p[2] + m[13]) / cw;
    return [r.left + (sx + 1) / 2 * r.width, r.top + (1 - sy) / 2 * r.height];
  };
  // the point drawn at a pixel: of the points whose square covers it (the shader's size), the
  // nearest to the eye; where none covers it, the nearest within 6 pixels
  function pick(cx, cy) {
    const r = canvas.getBoundingClientRect(), m = mvp(), dpr = window.devicePixelRatio || 1;
    const px = (cx - r.left) / r.width * 2 - 1, py = 1 - (cy - r.top) / r.height * 2;
    const proj = canvas.height / (2 * Math.tan(cam.fov / 2)), toPx = r.width / 2;
    const tol = 6 / toPx, toly = 6 / (r.height / 2);
    let best = null, bestD = Infinity, near = null, nearD = Infinity;
    for (const b of V.batches) {
      const p = b.pos;
      for (let i = 0; i < b.n; i++) {
        if (mask[b.cls[i]] < 0.5) continue;
        const x = p[3 * i], y = p[3 * i + 1], z = p[3 * i + 2];
        const cw = m[3] * x + m[7] * y + m[11] * z + m[15];
        if (cw <= 0) continue;
        const dx = (m[0] * x + m[4] * y + m[8] * z + m[12]) / cw - px;
        if (dx > tol || dx < -tol) continue;
        const dy = (m[1] * x + m[5] * y + m[9] * z + m[13]) / cw - py;
        if (dy > toly || dy < -toly) continue;
        const size = pointSize * dpr, sp = b.sp ? b.sp[i] : 0;
        const half = Math.min(Math.max(size, size / 4 * 1.2 * sp * proj / cw), 3 * size) / 2 / dpr; // CSS pixels
        const ex = Math.abs(dx) * toPx, ey = Math.abs(dy) * r.height / 2;
        if (ex <= half + 0.5 && ey <= half + 0.5) { if (cw < bestD) { bestD = cw; best = [b, i]; } }
        else { const d = Math.hypot(ex, ey); if (d < nearD) { nearD = d; near = [b, i]; } }
      }
    }
    return best || near;
  }
  const fmt = (v, d = 3) => (v === null || v === undefined ? "–" : typeof v === "number" ? +v.toFixed(d) : v);
  async function select(cx, cy) {
    const hit = pick(cx, cy);
    if (!hit) { V.lastPick = null; $("element").textContent = "no point there"; setHighlight(null); return null; }
    const [b, i] = hit, o = meta.origin;
    const info = { "class": meta.classes[b.cls[i]].name, classId: b.cls[i], instance: b.instance[i], score: b.score[i],
      segment: b.segment[i], leaf: b.leaf[i], xyz: [b.pos[3 * i] + o[0], b.pos[3 * i + 1] + o[1], b.pos[3 * i + 2] + o[2]] };
    const r = await fetch(`/api/element?instance=${info.instance}&segment=${info.segment}&leaf=${info.leaf}`);
    const el = r.ok ? await r.json() : { path: [], error: await r.text() };
    Object.assign(info, { n_points: el.n_points, bbox: el.bbox, path: el.path, tree: el.tree });
    V.lastPick = info;
    const inst = info.instance;
    if (inst > 0) setHighlight((bb, j) => bb.instance[j] === inst);
    else setHighlight((bb, j) => bb.segment[j] === info.segment && bb.leaf[j] === info.leaf);
    const box = el.bbox ? el.bbox.map((v, k) => fmt(v + o[k % 3], 2)) : null;
    const rows = [["class", info["class"]], ["instance", inst || "none"], ["score", fmt(info.score)],
      ["element points", el.n_points == null ? "–" : el.n_points.toLocaleString("en-US")],
      ["box min", box ? box.slice(0, 3).join(", ") : "–"], ["box max", box ? box.slice(3).join(", ") : "–"],
      ["point", info.xyz.map((v) => fmt(v, 3)).join(", ")], ["segment", info.segment + " / leaf " + info.leaf]];
    let html = "<table>" + rows.map(([k, v]) => `<tr><td class="muted">${k}</td><td>${v}</td></tr>`).join("") + "</table>";
    if (el.path && el.path.length) {
      html += `<div class="muted" style="margin-top:6px">tree ${el.tree}: root to leaf</div><ol class="path" id="path">` + el.path.map((n) =>
        `<li data-tree="${n.tree}" data-node="${n.node}">node ${n.node} · ${n.sequence} · ${n["class"]} ${fmt(n.score, 2)}` +
        (n.xi !== null ? ` · split ${fmt(n.xi, 3)}` : "") + (n.energy.some((e) => e !== null) ? ` · E [${n.energy.map((e) => fmt(e, 2)).join(", ")}]` : "") +
        ` · ${(n.n_points || 0).toLocaleString("en-US")} pts</li>`).join("") + "</ol>";
    } else html += `<div class="muted">no tree node for this point</div>`;
    $("element").innerHTML = html;
    $("element").classList.remove("muted");
    return info;
  }
  const report = (err) => { V.errors.push(String(err)); console.warn(err); };
  $("element").addEventListener("click", (e) => { const li = e.target.closest("li[data-node]"); if (li) showNode(+li.dataset.tree, +li.dataset.node).catch(report); });

  // ------------------------------------------------------------------ the tree outline
  async function showNode(tree, node) {
    const s = await (await fetch(`/api/subtree?tree=${tree}&node=${node}`)).json();
    const segs = new Set(s.segments), ns = new Set(s.nodes);
    setHighlight((b, i) => segs.has(b.segment[i]) && ns.has(b.leaf[i]));
    document.querySelectorAll(".outline .lab.on").forEach((x) => x.classList.remove("on"));
    const lab = document.querySelector(`.outline li[data-key="${tree}/${node}"] > .lab`); if (lab) lab.classList.add("on");
  }
  V.showNode = showNode;
  function item(n) {
    const li = document.createElement("li");
    li.dataset.key = n.tree + "/" + n.node;
    const tw = n.n_children ? "▸" : "·";
    li.innerHTML = `<span class="tw">${tw}</span><span class="lab">${n.node === 0 && n.depth === 0 ? "tree " + n.tree : "node " + n.node} ` +
      `<span class="muted">${n.sequence} · ${n["class"]} · ${(n.n_points || 0).toLocaleString("en-US")}${n.xi !== null ? " · " + fmt(n.xi, 2) : ""}</span></span>`;
    li.querySelector(".lab").addEventListener("click", () => showNode(n.tree, n.node).catch(report));
    if (n.n_children) li.querySelector(".tw").addEventListener("click", async (e) => {
      const t = e.target;
      const sub = li.querySelector("ul");
      if (sub) { sub.remove(); t.textContent = "▸"; return; }
      const r = await (await fetch(`/api/children?tree=${n.tree}&node=${n.node}`)).json();
      const ul = document.createElement("ul"); r.children.forEach((c) => ul.appendChild(item(c))); li.appendChild(ul); t.textContent = "▾";
    });
    return li;
  }
  async function outline() {
    const r = await (await fetch("/api/tree?limit=300")).json();
    const ul = $("tree"); r.roots.forEach((n) => ul.appendChild(item(n)));
    $("treecount").textContent = r.total > r.roots.length ? `(largest ${r.roots.length} of ${r.total})` : `(${r.total} trees)`;
  }

  // ------------------------------------------------------------------ input
  let drag = null;
  canvas.addEventListener("contextmenu", (e) => e.preventDefault());
  canvas.addEventListener("mousedown", (e) => { drag = { x: e.clientX, y: e.clientY, x0: e.clientX, y0: e.clientY, pan: e.button === 2 || e.shiftKey }; });
  window.addEventListener("mouseup", (e) => {
    if (drag && Math.hypot(e.clientX - drag.x0, e.clientY - drag.y0) < 4 && e.button === 0)
      select(e.clientX, e.clientY).catch((err) => { V.errors.push(String(err)); $("element").textContent = "error: " + err; });
    drag = null;
  });
  window.addEventListener("mousemove", (e) => {
    if (!drag) return;
    const dx = e.clientX - drag.x, dy = e.clientY - drag.y; drag.x = e.clientX; drag.y = e.clientY;
    if (drag.pan) {
      const s = cam.dist * Math.tan(cam.fov / 2) * 2 / canvas.clientHeight;
      const cy = Math.cos(cam.yaw), sy = Math.sin(cam.yaw);
      cam.target[0] += s * (dx * sy + dy * cy * Math.sin(cam.pitch)); cam.target[1] += s * (-dx * cy + dy * sy * Math.sin(cam.pitch));
    } else { cam.yaw -= dx * 0.008; cam.pitch = Math.min(1.55, Math.max(-0.2, cam.pitch + dy * 0.008)); }
    moved();
  });
  canvas.addEventListener("wheel", (e) => { e.preventDefault(); cam.dist *= Math.exp(e.deltaY * 0.0012); moved(); }, { passive: false });
  window.addEventListener("keydown", (e) => {
    if (e.key === "f" || e.key === "F") { fit(V.dataBox || meta.bounds); moved(); }
    if (e.key === "Escape") { setHighlight(null); document.querySelectorAll(".outline .lab.on").forEach((x) => x.classList.remove("on")); }
  });
  window.addEventListener("resize", () => { dirty = true; });
  $("mode").addEventListener("change", (e) => { mode = e.target.value; recolour(); });
  $("size").addEventListener("input", (e) => { pointSize = +e.target.value; dirty = true; });
  V.setMode = (m) => { mode = m; $("mode").value = m; recolour(); };
  V.camera = cam;
  V.redraw = () => { draw(); return true; };
  V.pickAt = select;

  // the loaded points' extent without stray far points: 1st..99th percentile of a sample
  function dataBox() {
    const xs = [[], [], []];
    for (const b of V.batches) for (let i = 0; i < b.n; i += 13) for (let k = 0; k < 3; k++) xs[k].push(b.pos[3 * i + k]);
    if (!xs[0].length) return meta.bounds;
    const q = (a, f) => a[Math.min(a.length - 1, Math.floor(f * a.length))];
    xs.forEach((a) => a.sort((u, v) => u - v));
    return [q(xs[0], 0.04), q(xs[1], 0.04), q(xs[2], 0.01), q(xs[0], 0.96), q(xs[1], 0.96), q(xs[2], 0.99)];
  }

  // ------------------------------------------------------------------ start
  async function start() {
    const t0 = performance.now();
    meta = await (await fetch("/api/meta")).json();
    V.meta = meta;
    $("store").textContent = meta.store;
    document.title = "hollowtree view: " + meta.store;
    for (const n of meta.nodes) nodes.set(n.tile + "/" + n.chunk, { ...n, level: -1, pending: false, box: null });
    legend();
    fit(meta.bounds);
    requestAnimationFrame((t) => { lastDraw = t; loop(t); });
    const first = meta.first_view.map((f) => () => fetchNode(nodes.get(f.tile + "/" + f.chunk), f.level));
    await pool(first);
    V.dataBox = dataBox(); fit(V.dataBox);
    draw();
    V.firstViewMs = performance.now() - t0;
    V.ready = true;
    outline().catch((e) => { V.errors.push(String(e)); console.warn(e); });
    refine();
  }
  window.addEventListener("error", (e) => V.errors.push(String(e.message || e)));
  start().catch((e) => { V.errors.push(String(e)); console.error(e); $("status").textContent = "error: " + e; });
})();
