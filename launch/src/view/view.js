// troupe view: draws the worlds the server describes and the frames it streams.
"use strict";

const canvas = document.getElementById("world");
const ctx = canvas.getContext("2d");
const statusLine = document.getElementById("status");
const followSelect = document.getElementById("follow");
const deviceTable = document.getElementById("devices");

let worlds = [];          // from /api/world
let frame = null;         // the newest frame
let deviceCount = -1;     // devices listed, to refresh the table when it changes
const params = new URLSearchParams(location.search);
const view = { x: 0, y: 0, scale: 40, fixed: params.has("scale") };
if (view.fixed) {
  view.x = parseFloat(params.get("x") || "0");
  view.y = parseFloat(params.get("y") || "0");
  view.scale = parseFloat(params.get("scale"));
}
let follow = params.get("follow") || "";

// The world frame to the canvas: x right, y up, `scale` pixels per metre.
function toScreen(x, y) {
  return [canvas.width / 2 + (x - view.x) * view.scale,
          canvas.height / 2 - (y - view.y) * view.scale];
}

function compose(a, b) {
  const c = Math.cos(a[2]), s = Math.sin(a[2]);
  return [a[0] + b[0] * c - b[1] * s, a[1] + b[0] * s + b[1] * c, a[2] + b[2]];
}

// A model's pose in the world: streamed if it moves, as described if not.
function poseOf(world, id) {
  const live = frame && frame.poses[world.simulation];
  if (live && live[id]) return live[id];
  return world.models[id].pose;
}

function fit() {
  let lo = [Infinity, Infinity], hi = [-Infinity, -Infinity];
  for (const w of worlds) {
    w.models.forEach((m, id) => {
      const p = poseOf(w, id);
      for (const poly of m.polys) for (const q of poly) {
        const g = compose(p, [q[0], q[1], 0]);
        lo = [Math.min(lo[0], g[0]), Math.min(lo[1], g[1])];
        hi = [Math.max(hi[0], g[0]), Math.max(hi[1], g[1])];
      }
    });
  }
  if (!isFinite(lo[0])) return;
  view.x = (lo[0] + hi[0]) / 2;
  view.y = (lo[1] + hi[1]) / 2;
  view.scale = 0.95 * Math.min(canvas.width / (hi[0] - lo[0] || 1), canvas.height / (hi[1] - lo[1] || 1));
}

function drawModel(w, id) {
  const m = w.models[id];
  if (!m.polys.length) return;
  const p = poseOf(w, id);
  ctx.fillStyle = m.color;
  ctx.strokeStyle = m.moves ? "#000" : m.color;
  ctx.lineWidth = 1;
  for (const poly of m.polys) {
    ctx.beginPath();
    poly.forEach((q, k) => {
      const [sx, sy] = toScreen(...compose(p, [q[0], q[1], 0]));
      if (k === 0) ctx.moveTo(sx, sy); else ctx.lineTo(sx, sy);
    });
    ctx.closePath();
    ctx.fill();
    if (m.moves) ctx.stroke();
  }
}

// Rays of one range device: a laser's fan, or a ranger's sensors (a fan each,
// or one ray each when the device reports one reading per sensor).
function drawScan(w, d) {
  const scan = frame && frame.scans[d.device];
  if (!scan || !d.sensors.length) return;
  const base = poseOf(w, d.model);
  const rays = [];
  if (scan.kind === "laser") {
    const s = compose(base, d.sensors[0].pose);
    scan.ranges.forEach((r, k) => rays.push([s, scan.min + k * scan.res, r]));
  } else {
    const total = d.sensors.reduce((n, s) => n + s.samples, 0);
    let k = 0;
    for (const sensor of d.sensors) {
      const s = compose(base, sensor.pose);
      if (scan.ranges.length === total) {
        for (let i = 0; i < sensor.samples; i++, k++) {
          const a = sensor.samples > 1 ? -sensor.fov / 2 + i * sensor.fov / (sensor.samples - 1) : 0;
          rays.push([s, a, scan.ranges[k]]);
        }
      } else if (k < scan.ranges.length) {
        rays.push([s, 0, scan.ranges[k++]]);
      }
    }
  }
  ctx.strokeStyle = scan.kind === "laser" ? "rgba(0,0,255,0.18)" : "rgba(0,160,0,0.35)";
  ctx.lineWidth = 1;
  ctx.beginPath();
  for (const [s, a, r] of rays) {
    const [x0, y0] = toScreen(s[0], s[1]);
    const [x1, y1] = toScreen(s[0] + r * Math.cos(s[2] + a), s[1] + r * Math.sin(s[2] + a));
    ctx.moveTo(x0, y0);
    ctx.lineTo(x1, y1);
  }
  ctx.stroke();
}

// The canvas as large as the page lays it out.
function size() {
  const r = canvas.getBoundingClientRect();
  if (canvas.width !== Math.round(r.width) || canvas.height !== Math.round(r.height)) {
    canvas.width = Math.round(r.width);
    canvas.height = Math.round(r.height);
  }
}

function draw() {
  size();
  if (follow) {
    for (const w of worlds) {
      const id = w.models.findIndex(m => m.name === follow);
      if (id >= 0) { const p = poseOf(w, id); view.x = p[0]; view.y = p[1]; }
    }
  }
  ctx.fillStyle = "#fff";
  ctx.fillRect(0, 0, canvas.width, canvas.height);
  for (const w of worlds) {
    // The still world first, then what moves, each over its parent.
    w.models.forEach((m, id) => { if (!m.moves) drawModel(w, id); });
    w.models.forEach((m, id) => { if (m.moves) drawModel(w, id); });
    for (const d of w.devices) drawScan(w, d);
    ctx.fillStyle = "#000";
    ctx.font = "12px system-ui, sans-serif";
    w.models.forEach((m, id) => {
      if (m.moves && m.parent === null) {
        const p = poseOf(w, id);
        const [sx, sy] = toScreen(p[0], p[1]);
        ctx.fillText(m.name, sx + 8, sy - 8);
      }
    });
  }
  const parts = [];
  if (frame && frame.time !== null) parts.push(`${frame.time.toFixed(1)} s simulated`);
  if (frame && frame.speed !== null) parts.push(`${frame.speed.toFixed(1)}× real time`);
  if (frame) parts.push(`${frame.devices} devices`);
  if (!worlds.length) parts.push("no simulator yet");
  statusLine.textContent = parts.join(" · ") || "waiting for data…";
}

let drawing = false;
function redraw() {
  if (drawing) return;
  drawing = true;
  requestAnimationFrame(() => { drawing = false; draw(); });
}

async function getJson(path) {
  const r = await fetch(path, { cache: "no-store" });
  if (!r.ok) throw new Error(`${path}: ${r.status}`);
  return r.json();
}

async function loadWorlds() {
  worlds = (await getJson("/api/world")).worlds;
  const names = [];
  for (const w of worlds) for (const m of w.models) if (m.moves && m.parent === null) names.push(m.name);
  followSelect.innerHTML = '<option value="">(nothing)</option>' +
    names.map(n => `<option${n === follow ? " selected" : ""}>${n}</option>`).join("");
}

async function loadDevices() {
  const list = await getJson("/api/devices");
  deviceCount = list.length;
  deviceTable.innerHTML = list.map(d =>
    `<tr><td class="robot">${d.robot}</td><td>${d.device}</td><td>${d.driver}</td></tr>`).join("");
}

function onFrame(f) {
  frame = f;
  const known = new Set(worlds.map(w => w.simulation));
  if (Object.keys(f.poses).some(s => !known.has(s))) loadWorlds().then(redraw, () => {});
  if (f.devices !== deviceCount) loadDevices().catch(() => {});
  redraw();
}

followSelect.addEventListener("change", () => { follow = followSelect.value; redraw(); });

let drag = null;
canvas.addEventListener("mousedown", e => { drag = [e.clientX, e.clientY]; canvas.classList.add("dragging"); });
window.addEventListener("mouseup", () => { drag = null; canvas.classList.remove("dragging"); });
window.addEventListener("mousemove", e => {
  if (!drag) return;
  view.x -= (e.clientX - drag[0]) / view.scale;
  view.y += (e.clientY - drag[1]) / view.scale;
  drag = [e.clientX, e.clientY];
  follow = "";
  followSelect.value = "";
  redraw();
});
canvas.addEventListener("wheel", e => {
  e.preventDefault();
  const r = canvas.getBoundingClientRect();
  const mx = e.clientX - r.left - canvas.width / 2, my = e.clientY - r.top - canvas.height / 2;
  const before = [view.x + mx / view.scale, view.y - my / view.scale];
  view.scale *= Math.exp(-e.deltaY * 0.001);
  view.x = before[0] - mx / view.scale;
  view.y = before[1] + my / view.scale;
  redraw();
}, { passive: false });
window.addEventListener("resize", redraw);

(async () => {
  try {
    await loadWorlds();
    await loadDevices();
    frame = await getJson("/api/frame");
  } catch (e) {
    statusLine.textContent = `cannot reach the view server: ${e.message}`;
  }
  size();
  if (!view.fixed) fit();
  draw();
  document.body.dataset.ready = "1";
  const events = new EventSource("/api/stream");
  events.onmessage = m => onFrame(JSON.parse(m.data));
  events.onerror = () => { statusLine.textContent = "reconnecting to the view server…"; };
})();
