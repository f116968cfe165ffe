// The editor page's script (served as page.js: the page runs nothing inline).
"use strict";
const token = new URLSearchParams(location.search).get("t") || "";
const $ = (id) => document.getElementById(id);
const canvas = $("gl"), overlay = $("overlay"), octx = overlay.getContext("2d");
const gl = canvas.getContext("webgl2", { antialias: true, preserveDrawingBuffer: true });
const rc = window.rc = { ready: false, updates: 0, roundTrips: [], frameTimes: [], released: 0, messages: [] };

// ---------- small matrix helpers (column-major, as WebGL wants) ----------
function mul(a, b) { const o = new Float64Array(16); for (let c = 0; c < 4; c++) for (let r = 0; r < 4; r++) { let s = 0; for (let k = 0; k < 4; k++) s += a[k * 4 + r] * b[c * 4 + k]; o[c * 4 + r] = s; } return o; }
function perspective(fovy, aspect, near, far) { const f = 1 / Math.tan(fovy / 2), o = new Float64Array(16); o[0] = f / aspect; o[5] = f; o[10] = (far + near) / (near - far); o[11] = -1; o[14] = 2 * far * near / (near - far); return o; }
function lookAt(eye, at, up) { const z = norm(sub(eye, at)), x = norm(cross(up, z)), y = cross(z, x); const o = new Float64Array(16); o[0] = x[0]; o[4] = x[1]; o[8] = x[2]; o[1] = y[0]; o[5] = y[1]; o[9] = y[2]; o[2] = z[0]; o[6] = z[1]; o[10] = z[2]; o[12] = -dot(x, eye); o[13] = -dot(y, eye); o[14] = -dot(z, eye); o[15] = 1; return o; }
const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]], add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
const scl = (a, s) => [a[0] * s, a[1] * s, a[2] * s], dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const norm = (a) => { const l = Math.hypot(a[0], a[1], a[2]) || 1; return [a[0] / l, a[1] / l, a[2] / l]; };
// Quaternions [w, x, y, z] for composing the handle's turns.
function quat(axis, deg) { const h = deg * Math.PI / 360, s = Math.sin(h), a = norm(axis); return [Math.cos(h), a[0] * s, a[1] * s, a[2] * s]; }
function qmul(a, b) { return [a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3], a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2], a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1], a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0]]; }
function axisAngle(q) { const w = Math.max(-1, Math.min(1, q[0])), s = Math.sqrt(1 - w * w); const deg = 2 * Math.acos(w) * 180 / Math.PI; return s < 1e-9 ? { axis: [0, 0, 1], degrees: 0 } : { axis: [q[1] / s, q[2] / s, q[3] / s], degrees: deg }; }
function qrot(q, v) { const p = qmul(qmul(q, [0, v[0], v[1], v[2]]), [q[0], -q[1], -q[2], -q[3]]); return [p[1], p[2], p[3]]; }

// ---------- state ----------
let scene, N = 0, pos, classes, cellData, tris;
let edit = { fixed: [], handles: [], pins: [] };
let masks = { fixed: [], handles: [] };        // per selection: Uint8Array of the proxy samples it holds
let active = 0, mode = "view", showStrain = false, showCells = false, display = 0; // 0 rest, 1 blended, 2 final
let xray = false;                                // Box and Lasso: through the shape, or only what is visible
const maskCache = new Map(), maskWaiting = new Map(), selectKeys = new Map(); let selectSeq = 0;
let history = [], future = [], seq = 0, sentAt = new Map(), motionsSeen = false;
const cam = { az: -60, el: 25, dist: 1, target: [0, 0, 0] };

async function get(name) { const r = await fetch(name + "?t=" + token); if (!r.ok) throw new Error(name + ": " + r.status); return r; }

// ---------- WebGL ----------
const VS = `#version 300 es
precision highp float; precision highp int; precision highp sampler2D;
in vec3 aPos; in vec3 aColor; in uvec4 aCells; in vec4 aWeights; in vec3 aFinal; in float aRole;
uniform mat4 uMVP; uniform sampler2D uMotions; uniform int uMode; uniform int uStrain; uniform float uPointSize; uniform float uStrainMax;
out vec3 vColor; out vec3 vPos;
vec4 texel(uint cell, int row) { int i = int(cell) * 4 + row; return texelFetch(uMotions, ivec2(i % 4096, i / 4096), 0); }
vec3 heat(float t) { t = clamp(t, 0.0, 1.0); return vec3(smoothstep(0.0, 0.5, t) , smoothstep(0.25, 0.75, t) * (1.0 - smoothstep(0.75, 1.0, t)) + 0.2 * (1.0 - t), 1.0 - smoothstep(0.0, 0.5, t)); }
void main() {
  vec3 p = aPos; float strain = 0.0;
  if (uMode == 1) {
    vec3 q = vec3(0.0); float ws = 0.0;
    for (int k = 0; k < 4; k++) {
      float w = aWeights[k]; if (w <= 0.0) continue;
      uint c = aCells[k];
      vec4 r0 = texel(c, 0), r1 = texel(c, 1), r2 = texel(c, 2);
      q += w * vec3(dot(r0.xyz, p) + r0.w, dot(r1.xyz, p) + r1.w, dot(r2.xyz, p) + r2.w);
      strain += w * texel(c, 3).x; ws += w;
    }
    if (ws > 0.0) p = q / ws;
  } else if (uMode == 2) { p = aFinal; }
  vPos = p;
  gl_Position = uMVP * vec4(p, 1.0);
  gl_PointSize = uPointSize;
  vec3 c = aColor;
  if (uStrain == 1 && uMode == 1) c = heat(strain / max(uStrainMax, 1e-12));
  if (aRole > 0.5 && aRole < 1.5) c = mix(c, vec3(0.25, 0.45, 1.0), 0.75);
  else if (aRole > 1.5 && aRole < 2.5) c = mix(c, vec3(1.0, 0.2, 0.9), 0.8);
  else if (aRole > 2.5) { float h = aRole - 3.0; c = mix(c, vec3(1.0, 0.55 - 0.15 * mod(h, 3.0), 0.1 + 0.25 * mod(h, 2.0)), 0.75); }
  vColor = c;
}`;
const FS = `#version 300 es
precision highp float;
in vec3 vColor; in vec3 vPos; uniform int uShade; uniform vec3 uLight; out vec4 o;
void main() {
  vec3 c = vColor;
  if (uShade == 1) { vec3 n = normalize(cross(dFdx(vPos), dFdy(vPos))); c *= 0.35 + 0.65 * abs(dot(n, uLight)); }
  o = vec4(c, 1.0);
}`;
const LVS = `#version 300 es
precision highp float; precision highp int; precision highp sampler2D;
in vec3 aPos; in float aCell; uniform mat4 uMVP; uniform sampler2D uMotions; uniform int uMode; uniform vec3 uLineColor;
out vec3 vColor; out vec3 vPos;
vec4 texel(int cell, int row) { int i = cell * 4 + row; return texelFetch(uMotions, ivec2(i % 4096, i / 4096), 0); }
void main() {
  vec3 p = aPos; int c = int(aCell);
  if (uMode != 0 && c >= 0) { vec4 r0 = texel(c, 0), r1 = texel(c, 1), r2 = texel(c, 2); p = vec3(dot(r0.xyz, p) + r0.w, dot(r1.xyz, p) + r1.w, dot(r2.xyz, p) + r2.w); }
  vPos = p; vColor = uLineColor; gl_Position = uMVP * vec4(p, 1.0);
}`;
function program(vs, fs) {
  const p = gl.createProgram();
  for (const [type, src] of [[gl.VERTEX_SHADER, vs], [gl.FRAGMENT_SHADER, fs]]) {
    const s = gl.createShader(type); gl.shaderSource(s, src); gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
    gl.attachShader(p, s);
  }
  gl.linkProgram(p); if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(p));
  return p;
}
let prog, lprog, vao, roleBuf, finalBuf, motionTex, indexBuf, cellVao, cellCount = 0, boundsVao, strainMax = 1e-12;

function buffer(attr, data, size, type, integer, p = prog) {
  const loc = gl.getAttribLocation(p, attr); const b = gl.createBuffer();
  gl.bindBuffer(gl.ARRAY_BUFFER, b); gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW);
  if (loc >= 0) { gl.enableVertexAttribArray(loc); if (integer) gl.vertexAttribIPointer(loc, size, type, 0, 0); else gl.vertexAttribPointer(loc, size, type, type === gl.UNSIGNED_BYTE, 0, 0); }
  return b;
}

function motionTexture(cells, maps, strain) {
  const texels = Math.max(1, cells * 4), w = 4096, h = Math.max(1, Math.ceil(texels / w));
  const data = new Float32Array(w * h * 4);
  for (let c = 0; c < cells; c++) {
    for (let r = 0; r < 3; r++) { const o = (c * 4 + r) * 4; data[o] = maps[c * 12 + r * 3]; data[o + 1] = maps[c * 12 + r * 3 + 1]; data[o + 2] = maps[c * 12 + r * 3 + 2]; data[o + 3] = maps[c * 12 + 9 + r]; }
    data[(c * 4 + 3) * 4] = strain ? strain[c] : 0;
  }
  gl.bindTexture(gl.TEXTURE_2D, motionTex);
  gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32F, w, h, 0, gl.RGBA, gl.FLOAT, data);
}

function setupGL(colors, cellsBlend, weights) {
  prog = program(VS, FS); lprog = program(LVS, FS);
  vao = gl.createVertexArray(); gl.bindVertexArray(vao);
  buffer("aPos", pos, 3, gl.FLOAT);
  buffer("aColor", colors, 3, gl.UNSIGNED_BYTE);
  buffer("aCells", cellsBlend, 4, gl.UNSIGNED_INT, true);
  buffer("aWeights", weights, 4, gl.FLOAT);
  finalBuf = buffer("aFinal", pos, 3, gl.FLOAT);
  rc.roleArray = new Float32Array(N);
  roleBuf = buffer("aRole", rc.roleArray, 1, gl.FLOAT);
  if (tris.length) { indexBuf = gl.createBuffer(); gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, indexBuf); gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, tris, gl.STATIC_DRAW); }
  gl.bindVertexArray(null);
  motionTex = gl.createTexture(); gl.bindTexture(gl.TEXTURE_2D, motionTex);
  gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST); gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
  motionTexture(0, [], null);
  // Cells as wire boxes, each corner tagged with its cell so that they move with it.
  const nc = cellData.length / 4, corners = [], owner = [];
  const edges = [[0, 1], [2, 3], [4, 5], [6, 7], [0, 2], [1, 3], [4, 6], [5, 7], [0, 4], [1, 5], [2, 6], [3, 7]];
  for (let c = 0; c < nc; c++) {
    const h = cellData[c * 4 + 3] / 2, x = cellData[c * 4], y = cellData[c * 4 + 1], z = cellData[c * 4 + 2];
    for (const [a, b] of edges) for (const k of [a, b]) { corners.push(x + (k & 1 ? h : -h), y + (k & 2 ? h : -h), z + (k & 4 ? h : -h)); owner.push(c); }
  }
  cellCount = owner.length;
  cellVao = gl.createVertexArray(); gl.bindVertexArray(cellVao);
  buffer("aPos", new Float32Array(corners), 3, gl.FLOAT, false, lprog); buffer("aCell", new Float32Array(owner), 1, gl.FLOAT, false, lprog);
  const lo = scene.lo, hi = scene.hi, bc = [];
  for (const [a, b] of edges) for (const k of [a, b]) bc.push(k & 1 ? hi[0] : lo[0], k & 2 ? hi[1] : lo[1], k & 4 ? hi[2] : lo[2]);
  boundsVao = gl.createVertexArray(); gl.bindVertexArray(boundsVao);
  buffer("aPos", new Float32Array(bc), 3, gl.FLOAT, false, lprog); buffer("aCell", new Float32Array(24).fill(-1), 1, gl.FLOAT, false, lprog);
  gl.bindVertexArray(null);
}

// ---------- camera ----------
function upVec() { return scene.up === 1 ? [0, 1, 0] : scene.up === 0 ? [1, 0, 0] : [0, 0, 1]; }
function eye() {
  const a = cam.az * Math.PI / 180, e = cam.el * Math.PI / 180, u = upVec();
  // Two horizontal axes perpendicular to up.
  const h1 = scene.up === 2 ? [1, 0, 0] : scene.up === 1 ? [0, 0, 1] : [0, 1, 0], h2 = cross(u, h1);
  const d = add(add(scl(h1, Math.cos(e) * Math.cos(a)), scl(h2, Math.cos(e) * Math.sin(a))), scl(u, Math.sin(e)));
  return add(cam.target, scl(d, cam.dist));
}
function mvp() {
  const w = canvas.width, h = canvas.height, r = Math.hypot(...sub(scene.hi, scene.lo)) / 2 || 1;
  const proj = perspective(Math.PI / 4, w / h, Math.max(cam.dist - 4 * r, cam.dist * 0.01), cam.dist + 4 * r);
  return mul(proj, lookAt(eye(), cam.target, upVec()));
}
function project(m, p) { const x = m[0] * p[0] + m[4] * p[1] + m[8] * p[2] + m[12], y = m[1] * p[0] + m[5] * p[1] + m[9] * p[2] + m[13], w = m[3] * p[0] + m[7] * p[1] + m[11] * p[2] + m[15]; return [x / w, y / w, w]; }
const toScreen = (ndc) => [(ndc[0] + 1) / 2 * canvas.clientWidth, (1 - ndc[1]) / 2 * canvas.clientHeight];
const toNdc = (x, y) => [x / canvas.clientWidth * 2 - 1, 1 - y / canvas.clientHeight * 2];

// ---------- drawing ----------
let frameQueued = false;
function redraw() { if (!frameQueued) { frameQueued = true; requestAnimationFrame(draw); } }
function draw(t) {
  frameQueued = false;
  const start = performance.now();
  const w = canvas.clientWidth * devicePixelRatio, h = canvas.clientHeight * devicePixelRatio;
  if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; overlay.width = canvas.clientWidth; overlay.height = canvas.clientHeight; }
  gl.viewport(0, 0, canvas.width, canvas.height);
  gl.clearColor(0.125, 0.137, 0.165, 1); gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT); gl.enable(gl.DEPTH_TEST);
  const m = new Float32Array(mvp());
  gl.useProgram(prog); gl.bindVertexArray(vao);
  gl.activeTexture(gl.TEXTURE0); gl.bindTexture(gl.TEXTURE_2D, motionTex);
  gl.uniformMatrix4fv(gl.getUniformLocation(prog, "uMVP"), false, m);
  gl.uniform1i(gl.getUniformLocation(prog, "uMotions"), 0);
  gl.uniform1i(gl.getUniformLocation(prog, "uMode"), display);
  gl.uniform1i(gl.getUniformLocation(prog, "uStrain"), showStrain ? 1 : 0);
  gl.uniform1f(gl.getUniformLocation(prog, "uStrainMax"), strainMax);
  gl.uniform3fv(gl.getUniformLocation(prog, "uLight"), norm(sub(eye(), cam.target)));
  if (tris.length) {
    gl.uniform1i(gl.getUniformLocation(prog, "uShade"), 1);
    gl.drawElements(gl.TRIANGLES, tris.length, gl.UNSIGNED_INT, 0);
  } else {
    gl.uniform1i(gl.getUniformLocation(prog, "uShade"), 0);
    gl.uniform1f(gl.getUniformLocation(prog, "uPointSize"), Math.max(1.5, Math.min(6, 1200 / Math.sqrt(N)) * devicePixelRatio));
    gl.drawArrays(gl.POINTS, 0, N);
  }
  gl.useProgram(lprog); gl.uniformMatrix4fv(gl.getUniformLocation(lprog, "uMVP"), false, m);
  gl.uniform1i(gl.getUniformLocation(lprog, "uMotions"), 0); gl.uniform1i(gl.getUniformLocation(lprog, "uShade"), 0);
  gl.uniform1i(gl.getUniformLocation(lprog, "uMode"), display === 0 ? 0 : 1);
  gl.uniform3f(gl.getUniformLocation(lprog, "uLineColor"), 0.5, 0.5, 0.55);
  gl.bindVertexArray(boundsVao); gl.drawArrays(gl.LINES, 0, 24);
  if (showCells) { gl.uniform3f(gl.getUniformLocation(lprog, "uLineColor"), 0.3, 0.8, 0.5); gl.bindVertexArray(cellVao); gl.drawArrays(gl.LINES, 0, cellCount); }
  gl.bindVertexArray(null);
  // Measuring (rc.sync): read a pixel back, which waits for the frame to be drawn.
  if (rc.sync) gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, new Uint8Array(4));
  rc.frameTimes.push(performance.now() - start); if (rc.frameTimes.length > 600) rc.frameTimes.shift();
  drawOverlay();
}

// ---------- the gizmo: three axes, a ring, a center ----------
function gizmo() {
  const h = edit.handles[active]; if (!h || !h.selections.length) return null;
  // Its centre is the handle's samples' centroid: none until the server says which they are.
  if (h.selections.some((sel) => !maskCache.has(keyOf(sel)))) return null;
  const m = mvp(), at = add(h.pivot, h.translate), c = project(m, at); if (c[2] <= 0) return null;
  const r = Math.hypot(...sub(scene.hi, scene.lo)) * 0.12;
  const axes = [[1, 0, 0], [0, 1, 0], [0, 0, 1]].map((a) => { const e = project(m, add(at, scl(a, r))); return { dir: a, end: toScreen(e) }; });
  return { center: toScreen(c), axes, ring: 70, at };
}
function drawOverlay() {
  octx.clearRect(0, 0, overlay.width, overlay.height);
  if (drag && (drag.kind === "box" || drag.kind === "lasso")) {
    octx.strokeStyle = "#fff"; octx.setLineDash([5, 4]); octx.beginPath();
    drag.path.forEach((p, i) => i ? octx.lineTo(p[0], p[1]) : octx.moveTo(p[0], p[1])); octx.closePath(); octx.stroke(); octx.setLineDash([]);
  }
  const g = gizmo(); if (!g) return;
  const colors = ["#f44", "#4d4", "#48f"];
  g.axes.forEach((a, i) => { octx.strokeStyle = colors[i]; octx.lineWidth = 3; octx.beginPath(); octx.moveTo(...g.center); octx.lineTo(...a.end); octx.stroke(); octx.fillStyle = colors[i]; octx.beginPath(); octx.arc(a.end[0], a.end[1], 6, 0, 7); octx.fill(); });
  octx.strokeStyle = "#ff4"; octx.lineWidth = 2; octx.beginPath(); octx.arc(g.center[0], g.center[1], g.ring, 0, 7); octx.stroke();
  octx.fillStyle = "#fff"; octx.beginPath(); octx.arc(g.center[0], g.center[1], 8, 0, 7); octx.fill();
  octx.lineWidth = 1;
}
function gizmoHit(x, y) {
  const g = gizmo(); if (!g) return null;
  const d = (p) => Math.hypot(p[0] - x, p[1] - y);
  if (d(g.center) < 12) return { part: "center", g };
  for (const a of g.axes) {
    const s = sub([...a.end, 0], [...g.center, 0]), len2 = s[0] * s[0] + s[1] * s[1];
    const t = Math.max(0, Math.min(1, ((x - g.center[0]) * s[0] + (y - g.center[1]) * s[1]) / (len2 || 1)));
    if (Math.hypot(g.center[0] + t * s[0] - x, g.center[1] + t * s[1] - y) < 8 && t > 0.15) return { part: "axis", axis: a, g };
  }
  if (Math.abs(d(g.center) - g.ring) < 8) return { part: "ring", g };
  return null;
}

// ---------- selections ----------
function rowMajor(m) { const o = []; for (let r = 0; r < 4; r++) o.push([m[r], m[4 + r], m[8 + r], m[12 + r]]); return o; }
// Which samples a selection holds comes from the server (the library's rule, the one the CLI
// applies to the saved spec): a "select" message each, answered by a bit per sample, kept here.
const keyOf = (sel) => JSON.stringify(sel);
function maskOf(sel) { return maskCache.get(keyOf(sel)) || new Uint8Array(N); }
function allSelections() { return edit.fixed.concat(...edit.handles.map((h) => h.selections)); }
// Asks the server for the masks of `sels` not known yet; `done` once all are here.
function fetchMasks(sels, done) {
  let left = 1;
  const one = () => { if (--left === 0) done(); };
  for (const sel of sels) {
    const k = keyOf(sel); if (maskCache.has(k)) continue;
    left += 1;
    if (!maskWaiting.has(k)) {
      maskWaiting.set(k, []); selectSeq += 1; selectKeys.set(selectSeq, k);
      socket.send(JSON.stringify({ type: "select", seq: selectSeq, selection: sel }));
    }
    maskWaiting.get(k).push(one);
  }
  one();
}
function gotMask(s, mask) {
  const k = selectKeys.get(s); if (k === undefined) return;
  selectKeys.delete(s); maskCache.set(k, mask);
  const waiting = maskWaiting.get(k) || []; maskWaiting.delete(k); waiting.forEach((f) => f());
}
function rebuildMasks() {
  masks.fixed = edit.fixed.map(maskOf);
  masks.handles = edit.handles.map((h) => h.selections.map(maskOf));
  const role = rc.roleArray; role.fill(0);
  masks.fixed.forEach((m) => { for (let i = 0; i < N; i++) if (m[i]) role[i] = 1; });
  masks.handles.forEach((ms, k) => ms.forEach((m) => { for (let i = 0; i < N; i++) if (m[i]) role[i] = 3 + k; }));
  for (const p of edit.pins) { let best = -1, bd = Infinity; for (let i = 0; i < N; i++) { const d = (pos[3 * i] - p[0]) ** 2 + (pos[3 * i + 1] - p[1]) ** 2 + (pos[3 * i + 2] - p[2]) ** 2; if (d < bd) { bd = d; best = i; } } if (best >= 0) role[best] = 2; }
  gl.bindBuffer(gl.ARRAY_BUFFER, roleBuf); gl.bufferData(gl.ARRAY_BUFFER, role, gl.STATIC_DRAW);
}
function centroid(ms) {
  let s = [0, 0, 0], n = 0;
  for (const m of ms) for (let i = 0; i < N; i++) if (m[i]) { s[0] += pos[3 * i]; s[1] += pos[3 * i + 1]; s[2] += pos[3 * i + 2]; n++; }
  return n ? scl(s, 1 / n) : [0, 0, 0];
}
// The server's limits on an edit (scene.json): the page keeps within them, the server refuses
// what passes them.
function selectionCount(e) { return e.fixed.length + e.handles.reduce((n, h) => n + h.selections.length, 0); }
// Adds `sel` to the fixed regions or to a handle (the role chosen now) once the server says
// which samples it holds: a selection that holds none is not kept, and the page says so.
function addSelection(sel) {
  const fixed = $("role").value === "fixed", handle = active;
  status("selecting…");
  fetchMasks([sel], () => {
    const caught = countOf(maskOf(sel));
    if (caught === 0) { warn(`the ${fixed ? "fixed" : "handle"} selection caught no sample: nothing selected${xray ? "" : " (X-ray selects through the shape)"}`); status(`${scene.name}: the empty selection was not kept`); return; }
    // Built from the edit as it is now: other selections may have come in meanwhile.
    if (selectionCount(edit) >= scene.max_selections) { warn(`the editor takes at most ${scene.max_selections} selections: undo some first`); return; }
    if (!fixed && handle >= scene.max_handles) { warn(`the editor takes at most ${scene.max_handles} handles`); return; }
    const next = JSON.parse(JSON.stringify(edit));
    if (fixed) next.fixed.push(sel);
    else {
      if (!next.handles[handle]) { next.handles[handle] = { selections: [], translate: [0, 0, 0], axis: [0, 0, 1], degrees: 0, pivot: [0, 0, 0] }; }
      next.handles[handle].selections.push(sel);
    }
    if (!fits(next)) { warn(`the edit would pass the editor's limit of ${scene.max_message} bytes a message: draw fewer or simpler lassos`); return; }
    const what = fixed ? `fixed, selection ${next.fixed.length}` : `handle ${handle + 1}, selection ${next.handles[handle].selections.length}`;
    warn("");
    snapshot(); edit = next;
    caughtNote = `${what}: ${caught.toLocaleString("en")} of ${N.toLocaleString("en")} samples shown`;
    changed(true);
    status(caughtNote);
  });
}
let caughtNote = ""; // what the last selection caught, kept on the status line
function countOf(mask) { let c = 0; for (let i = 0; i < mask.length; i++) c += mask[i]; return c; }

// ---------- edits, history, the solver ----------
function snapshot() { history.push(JSON.stringify(edit)); future = []; }
function restore(text) { edit = JSON.parse(text); active = Math.min(active, Math.max(0, edit.handles.length - 1)); changed(true); }
function handleList() {
  const s = $("handle"), n = Math.max(1, edit.handles.length); s.innerHTML = "";
  for (let k = 0; k < n; k++) { const o = document.createElement("option"); o.value = k; o.textContent = "handle " + (k + 1); s.appendChild(o); }
  if (active >= n) { const o = document.createElement("option"); o.value = active; o.textContent = "handle " + (active + 1); s.appendChild(o); }
  s.value = active;
}
function changed(selections) {
  if (selections) {
    const missing = allSelections().filter((sel) => !maskCache.has(keyOf(sel)));
    if (missing.length) { fetchMasks(missing, () => changed(true)); return; }
    rebuildMasks();
    edit.handles.forEach((h, k) => { if (h.selections.length) { const c = centroid(masks.handles[k]); h.pivot = c; } });
    handleList();
  }
  send();
  redraw();
}
let socket;
function send() {
  if (!socket || socket.readyState !== 1) return;
  seq += 1; sentAt.set(seq, performance.now());
  socket.send(JSON.stringify({ type: "edit", seq, edit }));
}
// Whether a message carrying `e` stays within the server's limit (with room for a file name).
function fits(e) { return JSON.stringify({ type: "apply", name: "", overwrite: true, edit: e }).length + 1024 <= scene.max_message; }
function release() { if (socket && socket.readyState === 1) socket.send(JSON.stringify({ type: "release", seq })); }
function status(text) { $("status").textContent = text; }
function warn(text) { $("warn").textContent = text; }

function onMessage(ev) {
  if (typeof ev.data === "string") {
    const m = JSON.parse(ev.data); rc.messages.push(m);
    if (m.type === "error" && m.select !== undefined) { warn("error: " + m.message); gotMask(m.select, new Uint8Array(N)); }
    else if (m.type === "error") warn("error: " + m.message);
    else if (m.type === "exists") {
      // A file this editor did not write: replaced only when the user says so.
      const what = m.action === "save" ? "Save edit" : "Apply";
      if (confirm(`${m.path} exists and was not written by this editor.\nReplace it (${what})?`)) write(m.action, m.name, true);
      else status(`not replaced: ${m.path}`);
    }
    else if (m.type === "warning") warn("warning: " + m.message);
    else if (m.type === "saved") { status("saved " + m.path); warn(""); }
    else if (m.type === "progress") { $("progress").max = m.total || 1; $("progress").value = m.total ? m.done : 0; status(m.stage + (m.total ? ` ${m.done} / ${m.total}` : "…")); }
    else if (m.type === "applied") { $("progress").value = $("progress").max; status(`applied: ${m.output}, ${m.samples} samples, ${m.seconds.toFixed(1)} s`); if (m.warnings.length) warn(m.warnings.join("\n")); }
    return;
  }
  const dv = new DataView(ev.data), kind = dv.getUint32(0, true), s = dv.getUint32(4, true);
  if (kind === 1) {
    const cells = dv.getUint32(8, true), its = dv.getUint32(12, true), secs = dv.getFloat32(16, true);
    if (cells === 0) { display = 0; motionsSeen = false; status(`${scene.name}: nothing constrained yet`); redraw(); return; }
    const maps = new Float32Array(ev.data, 20, cells * 12), strain = new Float32Array(ev.data, 20 + cells * 48, cells);
    motionTexture(cells, maps, strain);
    strainMax = 1e-12; for (const v of strain) strainMax = Math.max(strainMax, v);
    strainLegend();
    display = 1; motionsSeen = true; rc.updates += 1;
    const t0 = sentAt.get(s); if (t0 !== undefined) { requestAnimationFrame(() => { rc.roundTrips.push(performance.now() - t0); }); }
    for (const k of sentAt.keys()) if (k <= s) sentAt.delete(k);
    warn("");
    status(`${scene.name}: ${N.toLocaleString("en")} of ${scene.total.toLocaleString("en")} samples, ${scene.cells.toLocaleString("en")} cells · solve ${its} iterations, ${(secs * 1000).toFixed(0)} ms` + (caughtNote ? ` · ${caughtNote}` : ""));
    redraw();
  } else if (kind === 3) {
    const n = dv.getUint32(8, true), bits = new Uint8Array(ev.data, 16), mask = new Uint8Array(n);
    for (let i = 0; i < n; i++) mask[i] = (bits[i >> 3] >> (i & 7)) & 1;
    gotMask(s, mask);
  } else if (kind === 2) {
    const n = dv.getUint32(8, true), folded = dv.getUint32(12, true), checked = dv.getUint32(16, true);
    if (s !== seq) return; // a newer edit is on its way
    const p = new Float32Array(ev.data, 20, n * 3);
    gl.bindBuffer(gl.ARRAY_BUFFER, finalBuf); gl.bufferData(gl.ARRAY_BUFFER, p, gl.STATIC_DRAW);
    rc.final = p; rc.released += 1;
    if (motionsSeen) display = 2;
    if (folded) warn(`warning: the deformation folds space over at ${folded} of ${checked} samples checked`);
    redraw();
  }
}

// ---------- pointer ----------
let drag = null;
canvas.addEventListener("contextmenu", (e) => e.preventDefault());
canvas.addEventListener("pointerdown", (e) => {
  canvas.setPointerCapture(e.pointerId);
  const x = e.offsetX, y = e.offsetY, hit = e.button === 0 ? gizmoHit(x, y) : null;
  if (hit) {
    const h = edit.handles[active]; snapshot();
    drag = { kind: "gizmo", hit, x, y, translate: h.translate.slice(), q: quat(h.axis, h.degrees), m: mvp() };
  } else if (e.button === 0 && (mode === "box" || mode === "lasso")) drag = { kind: mode, path: [[x, y]], x, y, gap: 3 };
  else if (e.button === 0 && mode === "pin") { pin(x, y); }
  else drag = { kind: e.shiftKey || e.button === 2 ? "pan" : "orbit", x, y };
});
canvas.addEventListener("pointermove", (e) => {
  if (!drag) return;
  const x = e.offsetX, y = e.offsetY, dx = x - drag.x, dy = y - drag.y;
  if (drag.kind === "orbit") { cam.az -= dx * 0.4; cam.el = Math.max(-89, Math.min(89, cam.el + dy * 0.4)); drag.x = x; drag.y = y; }
  else if (drag.kind === "pan") {
    const f = norm(sub(cam.target, eye())), r = norm(cross(f, upVec())), u = cross(r, f), k = cam.dist * 0.0015;
    cam.target = add(cam.target, add(scl(r, -dx * k), scl(u, dy * k))); drag.x = x; drag.y = y;
  } else if (drag.kind === "box") { drag.path = [[drag.x, drag.y], [x, drag.y], [x, y], [drag.x, y]]; }
  else if (drag.kind === "lasso") {
    // Vertices at least `gap` pixels apart, at most the server's limit: the edit stays small.
    const last = drag.path[drag.path.length - 1];
    if (Math.hypot(x - last[0], y - last[1]) >= drag.gap) drag.path.push([x, y]);
    if (drag.path.length > scene.max_polygon) { drag.path = drag.path.filter((_, i) => i % 2 === 0); drag.gap *= 2; }
  }
  else if (drag.kind === "gizmo") { moveGizmo(drag, x, y); send(); }
  redraw();
});
canvas.addEventListener("pointerup", (e) => {
  const d = drag; drag = null; if (!d) return;
  if (d.kind === "box" || d.kind === "lasso") {
    const path = d.path;
    if (path.length >= 3 && Math.abs(path[2][0] - path[0][0]) + Math.abs(path[2][1] - path[0][1]) > 3) {
      const round = (v) => Math.round(v * 1e6) / 1e6;
      const sel = { polygon: path.map((p) => toNdc(p[0], p[1]).map(round)), view: rowMajor(mvp()) };
      if (!xray) sel.visible = true;
      const cls = checkedClasses(); if (cls.length) sel.classification = cls;
      addSelection(sel);
    }
  } else if (d.kind === "gizmo") { release(); }
  redraw();
});
canvas.addEventListener("wheel", (e) => { e.preventDefault(); cam.dist *= Math.exp(e.deltaY * 0.001); redraw(); }, { passive: false });
// The world displacement that moves the screen point of `at` by (dx, dy) pixels, in the view plane.
function planeMove(m, at, dx, dy) {
  const c = project(m, at), w = c[2];
  const f = norm(sub(cam.target, eye())), r = norm(cross(f, upVec())), u = cross(r, f);
  const px = project(m, add(at, r)), py = project(m, add(at, u));
  const sx = (px[0] - c[0]) * canvas.clientWidth / 2, sy = (py[1] - c[1]) * canvas.clientHeight / 2;
  return add(scl(r, dx / (sx || 1)), scl(u, -dy / (sy || 1)));
}
function moveGizmo(d, x, y) {
  const h = edit.handles[active], g = d.hit.g, dx = x - d.x, dy = y - d.y;
  if (d.hit.part === "center") h.translate = add(d.translate, planeMove(d.m, g.at, dx, dy));
  else if (d.hit.part === "axis") {
    const s = sub([...d.hit.axis.end, 0], [...g.center, 0]), len = Math.hypot(s[0], s[1]) || 1;
    const along = (dx * s[0] + dy * s[1]) / len, r = Math.hypot(...sub(scene.hi, scene.lo)) * 0.12;
    h.translate = add(d.translate, scl(d.hit.axis.dir, along / len * r));
  } else {
    const a0 = Math.atan2(d.y - g.center[1], d.x - g.center[0]), a1 = Math.atan2(y - g.center[1], x - g.center[0]);
    const view = norm(sub(eye(), cam.target)), q = qmul(quat(view, -(a1 - a0) * 180 / Math.PI), d.q);
    const aa = axisAngle(q); h.axis = aa.axis; h.degrees = aa.degrees;
  }
}
function pin(x, y) {
  const m = mvp(); let best = -1, bd = 100;
  for (let i = 0; i < N; i++) { const c = project(m, [pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]]); if (c[2] <= 0) continue; const s = toScreen(c), d = Math.hypot(s[0] - x, s[1] - y); if (d < bd) { bd = d; best = i; } }
  if (best < 0) return;
  if (edit.pins.length >= scene.max_pins) { warn(`the editor takes at most ${scene.max_pins} pins`); return; }
  snapshot(); edit.pins.push([pos[3 * best], pos[3 * best + 1], pos[3 * best + 2]]); changed(true);
}
function checkedClasses() { return [...document.querySelectorAll("#classes input:checked")].map((c) => +c.value); }

// ---------- toolbar ----------
function setMode(m) { mode = m; for (const k of ["view", "box", "lasso", "pin"]) $("m-" + k).classList.toggle("on", k === m); }
function setXray(on) {
  xray = on; $("xray").classList.toggle("on", on);
  $("select-mode").textContent = on ? "selects: all under it (x-ray)" : "selects: visible surface";
}
for (const k of ["view", "box", "lasso", "pin"]) $("m-" + k).onclick = () => setMode(k);
$("handle").onchange = () => { active = +$("handle").value; redraw(); };
$("new-handle").onclick = () => { active = edit.handles.filter((h) => h.selections.length).length; $("role").value = "handle"; handleList(); redraw(); };
$("select-classes").onclick = () => { const cls = checkedClasses(); if (cls.length) addSelection({ classification: cls }); };
$("undo").onclick = () => { if (history.length) { future.push(JSON.stringify(edit)); restore(history.pop()); release(); } };
$("redo").onclick = () => { if (future.length) { history.push(JSON.stringify(edit)); restore(future.pop()); release(); } };
$("clear").onclick = () => { snapshot(); edit = { fixed: [], handles: [], pins: [] }; active = 0; changed(true); };
$("strain").onclick = () => { showStrain = !showStrain; $("strain").classList.toggle("on", showStrain); if (showStrain && display === 2) display = 1; strainLegend(); redraw(); };
// The legend's strain scale: shown with Strain, from rigid (blue) to this edit's most (red).
function strainLegend() {
  $("strain-scale").hidden = !showStrain;
  $("strain-high").textContent = strainMax > 1e-12 ? `most ${strainMax.toPrecision(2)}` : "most";
}
function toggleHelp() { $("help").hidden = !$("help").hidden; $("help-button").classList.toggle("on", !$("help").hidden); }
$("help-button").onclick = toggleHelp;
$("show-cells").onclick = () => { showCells = !showCells; $("show-cells").classList.toggle("on", showCells); redraw(); };
$("xray").onclick = () => setXray(!xray);
// Save and Apply write a plain file name into the server's folder; the server answers
// "exists" for a file it did not write, and the page asks before sending overwrite.
function write(action, name, overwrite) {
  warn("");
  if (action === "apply") { $("progress").value = 0; status(`applying into ${name}…`); } else status(`saving ${name}…`);
  socket.send(JSON.stringify({ type: action, name, edit, overwrite }));
}
$("save").onclick = () => { const n = $("spec-path").value.trim(); if (n) write("save", n, false); };
$("apply").onclick = () => { const n = $("out-path").value.trim(); if (n) write("apply", n, false); };
addEventListener("keydown", (e) => {
  if (e.key === "F1") { e.preventDefault(); toggleHelp(); return; }
  if (e.target.tagName === "INPUT") return;
  if ((e.ctrlKey || e.metaKey) && e.key === "z") $("undo").onclick();
  else if ((e.ctrlKey || e.metaKey) && (e.key === "y" || e.key === "Z")) $("redo").onclick();
});
addEventListener("resize", redraw);

// ---------- start ----------
(async () => {
  try {
    scene = await (await get("scene.json")).json();
    const bufs = await Promise.all(["points.bin", "colors.bin", "classes.bin", "triangles.bin", "cells.bin", "blend.bin"].map(async (n) => (await get(n)).arrayBuffer()));
    pos = new Float32Array(bufs[0]); N = pos.length / 3; classes = new Uint8Array(bufs[2]); tris = new Uint32Array(bufs[3]); cellData = new Float32Array(bufs[4]);
    const blendCells = new Uint32Array(bufs[5], 0, 4 * N), weights = new Float32Array(bufs[5], 16 * N, 4 * N);
    setupGL(new Uint8Array(bufs[1]), blendCells, weights);
    $("title").textContent = scene.name;
    const stem = scene.name.replace(/\.[^.]*$/, ""), ext = (scene.name.match(/\.[^.]*$/) || [""])[0];
    $("spec-path").value = stem + ".edit.toml"; $("out-path").value = stem + "_edited" + ext;
    $("out-dir").textContent = "into " + scene.out_dir; $("out-dir").title += ": " + scene.out_dir; setXray(false);
    $("select-classes").style.display = scene.classes.length ? "" : "none";
    for (const c of scene.classes) { const l = document.createElement("label"); l.innerHTML = `<input type="checkbox" value="${c}">class ${c}`; $("classes").appendChild(l); }
    const r = Math.hypot(...sub(scene.hi, scene.lo)) / 2 || 1; cam.dist = r * 2.6;
    if (scene.up === 2) { cam.az = -90; cam.el = 30; } else { cam.az = 90; cam.el = 20; }
    handleList();
    socket = new WebSocket(`ws://${location.host}/ws?t=${token}`); socket.binaryType = "arraybuffer";
    socket.onmessage = onMessage;
    socket.onopen = () => { rc.ready = true; status(`${scene.name}: ${N.toLocaleString("en")} of ${scene.total.toLocaleString("en")} samples, ${scene.cells.toLocaleString("en")} cells — select fixed and handle regions (Box, Lasso), then drag the gizmo`); };
    socket.onclose = () => status("disconnected from the server");
    redraw();
  } catch (e) { status("error: " + e.message); }
})();
rc.look = (az, el) => { cam.az = az; cam.el = el; redraw(); };
rc.state = () => ({ edit, display, seq, active, N, lo: scene.lo, hi: scene.hi });
rc.setEdit = (e) => { snapshot(); edit = e; changed(true); };
rc.xray = () => xray;
// For tests: how many proxy samples the edit's selections hold (fixed, each handle), once known.
rc.selectedCounts = () => { if (allSelections().some((s) => !maskCache.has(keyOf(s)))) return null; const n = (ms) => { let c = 0; for (let i = 0; i < N; i++) if (ms.some((m) => m[i])) c++; return c; }; return { fixed: n(masks.fixed), handles: masks.handles.map(n) }; };
rc.release = release;
rc.mvp = () => rowMajor(mvp());
// For tests and scripts: where a relative point lands on the page (CSS pixels), and the gizmo.
rc.screenOf = (p) => { const c = project(mvp(), p); const s = toScreen(c); const r = canvas.getBoundingClientRect(); return [s[0] + r.left, s[1] + r.top]; };
rc.gizmo = () => { const g = gizmo(); return g && { center: g.center, axes: g.axes.map((a) => a.end) }; };
