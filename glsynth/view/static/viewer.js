// glsynth view: the page. It keeps the camera (pose and focal length), sends it on every move,
// and draws the frames the server renders. Messages are checked by glsynth/view/protocol.py.
"use strict";

const $ = (id) => document.getElementById(id);
const canvas = $("frame");
const ctx = canvas.getContext("2d", { willReadFrequently: true });
const LIGHTS = ["sun_elevation_deg", "sun_azimuth_deg", "turbidity", "exposure"];
const cam = { R: null, p: null, focal: 24, dist: 20, sensor: 36 };  // R columns: right, up, back
let scene = null, current = -1, ws = null, moving = false, stillTimer = null;
const keys = new Set();

function send(message) { if (ws && ws.readyState === 1) ws.send(JSON.stringify(message)); }
function showError(text) { const e = $("error"); e.textContent = text; e.style.display = text ? "block" : "none"; }

// --- camera maths: 3x3 matrices as arrays of rows ---
const col = (R, j) => [R[0][j], R[1][j], R[2][j]];
const add = (a, b, s = 1) => a.map((v, i) => v + s * b[i]);
function rotation(axis, angle) {  // Rodrigues
  const [x, y, z] = axis, c = Math.cos(angle), s = Math.sin(angle), t = 1 - c;
  return [[t*x*x + c, t*x*y - s*z, t*x*z + s*y], [t*x*y + s*z, t*y*y + c, t*y*z - s*x],
          [t*x*z - s*y, t*y*z + s*x, t*z*z + c]];
}
const mul = (A, B) => A.map((row) => [0, 1, 2].map((j) => row[0]*B[0][j] + row[1]*B[1][j] + row[2]*B[2][j]));
const apply = (A, v) => A.map((row) => row[0]*v[0] + row[1]*v[1] + row[2]*v[2]);
function orthonormal(R) {  // Gram-Schmidt on the columns, so rounding never drifts
  let x = col(R, 0), y = col(R, 1);
  const n = (v) => { const l = Math.hypot(...v); return v.map((c) => c / l); };
  x = n(x); y = n(add(y, x, -(x[0]*y[0] + x[1]*y[1] + x[2]*y[2])));
  const z = [x[1]*y[2] - x[2]*y[1], x[2]*y[0] - x[0]*y[2], x[0]*y[1] - x[1]*y[0]];
  return [0, 1, 2].map((i) => [x[i], y[i], z[i]]);
}
function pose() {
  return [0, 1, 2].map((i) => [...cam.R[i], cam.p[i]]).concat([[0, 0, 0, 1]]);
}
function setPose(P, focal) {
  cam.R = [0, 1, 2].map((i) => P[i].slice(0, 3)); cam.p = [0, 1, 2].map((i) => P[i][3]);
  cam.focal = focal; $("focal").value = focal;
}
function target() { return add(cam.p, col(cam.R, 2), -cam.dist); }
function orbit(dx, dy) {
  const t = target();
  const turn = mul(rotation([0, 0, 1], -dx * 0.005), rotation(col(cam.R, 0), -dy * 0.005));
  cam.R = orthonormal(mul(turn, cam.R));
  cam.p = add(t, apply(turn, add(cam.p, t, -1)));
}
function pan(dx, dy) {
  const s = cam.dist * 0.0015;
  cam.p = add(add(cam.p, col(cam.R, 0), -dx * s), col(cam.R, 1), dy * s);
}
function dolly(amount) { cam.p = add(cam.p, col(cam.R, 2), -amount); cam.dist = Math.max(0.5, cam.dist - amount); }

function moved() {
  if (!cam.R) return;
  moving = true;
  showCamera();
  send({ type: "camera", pose: pose(), focal_mm: cam.focal, moving: true });
  clearTimeout(stillTimer);
  stillTimer = setTimeout(still, 200);
}
function still() {
  if (!cam.R || keys.size) return;
  moving = false;
  send({ type: "camera", pose: pose(), focal_mm: cam.focal, moving: false });
}
function showCamera() {
  const hfov = 2 * Math.atan(cam.sensor / 2 / cam.focal) * 180 / Math.PI;
  $("focal-text").textContent = `${cam.focal.toFixed(1)} mm on the ${cam.sensor} mm sensor (${hfov.toFixed(1)}° across)`;
}

// --- mouse and keys ---
let drag = null;
canvas.addEventListener("contextmenu", (e) => e.preventDefault());
canvas.addEventListener("mousedown", (e) => { drag = { x: e.clientX, y: e.clientY, pan: e.button === 2 || e.shiftKey, far: false }; canvas.focus(); });
window.addEventListener("mouseup", (e) => {
  if (drag && !drag.far && e.target === canvas) inspect(e, true);
  if (drag && drag.far) still();
  drag = null;
});
let lastHover = 0;
canvas.addEventListener("mousemove", (e) => {
  if (!drag) {
    if (performance.now() - lastHover > 150) { lastHover = performance.now(); inspect(e, false); }
    return;
  }
  const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
  if (!drag.far && Math.hypot(dx, dy) < 3) return;
  drag.far = true; drag.x = e.clientX; drag.y = e.clientY;
  (drag.pan ? pan : orbit)(dx, dy);
  moved();
});
canvas.addEventListener("wheel", (e) => { e.preventDefault(); dolly(-e.deltaY * 0.002 * cam.dist); moved(); }, { passive: false });
function inspect(e, click) {
  const r = canvas.getBoundingClientRect();
  const x = (e.clientX - r.left) / r.width, y = (e.clientY - r.top) / r.height;
  if (x >= 0 && x <= 1 && y >= 0 && y <= 1) send({ type: "inspect", x, y });
  if (click) $("inspect").dataset.clicked = "1";
}
const FLY = { w: [2, -1], s: [2, 1], a: [0, -1], d: [0, 1] };
window.addEventListener("keydown", (e) => {
  if (e.target.tagName === "INPUT" || e.target.tagName === "TEXTAREA") return;
  const k = e.key.toLowerCase();
  if (k === "n" || k === "p") return jump(current + (k === "n" ? 1 : -1));
  if (k === "+" || k === "=" || k === "-") { cam.focal = Math.min(200, Math.max(8, cam.focal * (k === "-" ? 0.95 : 1.05))); $("focal").value = cam.focal; return moved(); }
  if ("wasdqe".includes(k) && k.length === 1) keys.add(k);
});
window.addEventListener("keyup", (e) => { keys.delete(e.key.toLowerCase()); if (!keys.size && moving) setTimeout(still, 50); });
function fly() {
  if (keys.size && cam.R) {
    const step = Math.max(0.05, cam.dist * 0.02);
    for (const k of keys) {
      if (k in FLY) cam.p = add(cam.p, col(cam.R, FLY[k][0]), FLY[k][1] * step);
      if (k === "q" || k === "e") cam.p = add(cam.p, [0, 0, 1], (k === "e" ? 1 : -1) * step);
    }
    moved();
  }
  requestAnimationFrame(fly);
}
requestAnimationFrame(fly);

// --- sampled cameras ---
function jump(i) {
  if (!scene || i < 0 || i >= scene.cameras.length) return;
  current = i;
  const c = scene.cameras[i];
  setPose(c.pose, c.focal_mm); cam.dist = Math.max(2, c.distance_m);
  showCamera(); listCameras();
  send({ type: "camera", pose: pose(), focal_mm: cam.focal, moving: false });
}
function listCameras() {
  const box = $("cameras"); box.textContent = "";
  scene.cameras.forEach((c, i) => {
    const v = scene.verdicts[String(i)] || "…";
    const row = document.createElement("div");
    row.className = (i === current ? "current " : "") + (v !== "kept" && v !== "…" ? "removed" : "");
    row.textContent = `${i} ${c.kind} f=${c.focal_mm.toFixed(0)}mm s=${c.s_m.toFixed(0)}m ` +
      `d=${c.distance_m.toFixed(1)}m h=${c.height_m.toFixed(1)}m ${c.side > 0 ? "L" : "R"} · ${v}`;
    row.onclick = () => jump(i);
    box.appendChild(row);
  });
}

// --- controls ---
function sceneMessage(configToml) {
  const q = $("quality").value || null;
  return { type: "scene", seed: Number($("seed").value), env: Number($("env").value), quality: q, config_toml: configToml };
}
let configText = null;
$("open").onclick = () => send(sceneMessage(configText));
$("clear-config").onclick = () => { configText = null; $("config-file").value = ""; send(sceneMessage(null)); };
$("config-file").onchange = async (e) => {
  const file = e.target.files[0];
  if (!file) return;
  configText = await file.text();
  send(sceneMessage(configText));
};
for (const id of LIGHTS) {
  const input = $(id);
  input.oninput = () => { input.nextElementSibling.textContent = input.value; };
  input.onchange = () => send(Object.assign({ type: "lighting" }, ...LIGHTS.map((k) => ({ [k]: Number($(k).value) }))));
}
$("focal").oninput = () => { cam.focal = Number($("focal").value); moved(); };
$("save").onclick = () => send({ type: "save" });
$("copy").onclick = () => {
  const text = JSON.stringify({ pose: pose(), focal_mm: cam.focal, sensor_mm: cam.sensor });
  $("camera-json").value = text;
  if (navigator.clipboard) navigator.clipboard.writeText(text).catch(() => {});
};
function showPasses(passes, current = "color") {
  const box = $("passes"); box.textContent = "";
  for (const name of passes) {
    const label = document.createElement("label");
    label.innerHTML = `<input type="radio" name="pass" value="${name}"> ${name.replace("_", " ")}`;
    label.firstChild.checked = name === current;
    label.firstChild.onchange = () => send({ type: "pass", name });
    box.appendChild(label);
  }
}
function showLegend(legend) {
  const box = $("legend"); box.textContent = "";
  const rgb = (c) => `rgb(${c.join(",")})`;
  for (const s of legend.swatches || []) {
    const row = document.createElement("div");
    row.innerHTML = `<span class="swatch" style="background:${rgb(s.rgb)}"></span>${s.label}`;
    box.appendChild(row);
  }
  if (legend.scale) {
    const stops = legend.scale.map((s, i) => `${rgb(s.rgb)} ${(100 * i / (legend.scale.length - 1)).toFixed(0)}%`);
    box.innerHTML += `<div id="scale" style="background:linear-gradient(to right, ${stops.join(",")})"></div>` +
      `<div style="display:flex;justify-content:space-between">${legend.scale.map((s) => `<span>${s.value}</span>`).join("")}</div><div>${legend.unit}</div>`;
  }
}
function showLighting(values) {
  for (const k of LIGHTS) { $(k).value = values[k]; $(k).nextElementSibling.textContent = Number(values[k]).toFixed(2); }
}

// --- messages from the server ---
async function onFrame(buffer) {
  const view = new DataView(buffer);
  const n = view.getUint32(0);
  const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, 4, n)));
  const blob = new Blob([new Uint8Array(buffer, 4 + n)], { type: header.mime });
  const image = await createImageBitmap(blob, { colorSpaceConversion: "none", premultiplyAlpha: "none" });
  ctx.imageSmoothingEnabled = !header.still;
  ctx.drawImage(image, 0, 0, canvas.width, canvas.height);
  image.close();
  canvas.dataset.seq = header.seq; canvas.dataset.still = header.still; canvas.dataset.pass = header.pass;
  $("status").textContent = `${header.still ? "still" : "moving"} ${header.width}x${header.height} ${header.pass}: ` +
    `rendered in ${header.render_ms.toFixed(0)} ms, sent after ${header.total_ms.toFixed(0)} ms · frame ${header.seq}`;
}
const handlers = {
  hello: (m) => {
    showPasses(m.passes); $("status").textContent = "connected";
    for (const q of m.qualities) $("quality").add(new Option(q, q));
  },
  passes: (m) => showPasses(m.passes, m.current),
  progress: (m) => { $("progress").value = m.fraction; $("stage").textContent = `env ${m.env}: ${m.stage}`; },
  scene: (m) => {
    const first = !scene || scene.env !== m.env || scene.seed !== m.seed;
    scene = m; canvas.width = m.size[0]; canvas.height = m.size[1]; cam.sensor = m.sensor_mm;
    $("seed").value = m.seed; $("env").value = m.env; $("quality").value = m.quality || "";
    $("progress").value = 1; $("stage").textContent = `env ${m.env} ready` + (m.seconds ? ` in ${m.seconds.toFixed(1)} s` : "");
    showLighting(m.lighting); showError("");
    if (first || !cam.R) jump(Math.max(0, Math.min(current, m.cameras.length - 1))); else listCameras();
  },
  lighting: (m) => { showLighting(m.lighting); scene.verdicts = {}; listCameras(); },
  verdict: (m) => { scene.verdicts[String(m.index)] = m.verdict; listCameras(); },
  legend: (m) => showLegend(m.legend),
  inspect: (m) => {
    $("inspect").textContent = `pixel (${m.col}, ${m.row}): ${m.component}, damage ${m.damage}, depth ${m.depth_m.toFixed(3)} m, part ${m.part || "none (sky)"}`;
    Object.assign($("inspect").dataset, { col: m.col, row: m.row });
    $("inspect").dataset.component = m.component; $("inspect").dataset.depth = m.depth_m; $("inspect").dataset.part = m.part || "";
  },
  saved: (m) => { $("saved").textContent = `saved ${m.folder}`; },
  error: (m) => showError(m.message),
};
function connect() {
  ws = new WebSocket(`ws://${location.host}/ws`);
  ws.binaryType = "arraybuffer";
  ws.onmessage = (e) => {
    if (typeof e.data !== "string") return onFrame(e.data);
    const message = JSON.parse(e.data);
    handlers[message.type](message);
  };
  ws.onclose = () => { $("status").textContent = "disconnected: reload the page once the server runs"; };
}
showLegend({});
connect();
