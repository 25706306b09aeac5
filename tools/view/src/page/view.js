// troupe view: draws the worlds the server describes and the frames it streams.
"use strict";

const canvas = document.getElementById("world");
const ctx = canvas.getContext("2d");
const statusLine = document.getElementById("status");
const followSelect = document.getElementById("follow");
const deviceTable = document.getElementById("devices");
const plannerSelect = document.getElementById("planner");
const localizerSelect = document.getElementById("localizer");
const teleopSelect = document.getElementById("teleop");
const panel = document.getElementById("panel");
const spaceSelect = document.getElementById("space");

let worlds = [];          // from /api/world
let maps = [];            // map devices, from /api/world, each with its picture
let frame = null;         // the newest frame
let deviceCount = -1;     // devices listed, to refresh the table when it changes
let notice = null;        // a refused order, shown for a few seconds
const params = new URLSearchParams(location.search);
const view = { x: 0, y: 0, scale: 40, fixed: params.has("scale") };
if (view.fixed) {
  view.x = parseFloat(params.get("x") || "0");
  view.y = parseFloat(params.get("y") || "0");
  view.scale = parseFloat(params.get("scale"));
}
let follow = params.get("follow") || "";
// The namespace shown, of those the server watches (?ns=K, the first by
// default): its world is drawn, its devices listed and commanded.
const ns = parseInt(params.get("ns") || "0", 10) || 0;
const api = path => `${path}${path.includes("?") ? "&" : "?"}ns=${ns}`;
let mapVersion = 0;                         // the server's count of map pictures: a new one is loaded
let chosen = params.get("device") || "";   // the device whose panel is open ("6665:laser:0")

// The world frame to the canvas: x right, y up, `scale` pixels per metre.
function toScreen(x, y) {
  return [canvas.width / 2 + (x - view.x) * view.scale,
          canvas.height / 2 - (y - view.y) * view.scale];
}

function compose(a, b) {
  const c = Math.cos(a[2]), s = Math.sin(a[2]);
  return [a[0] + b[0] * c - b[1] * s, a[1] + b[0] * s + b[1] * c, a[2] + b[2]];
}

// Each simulation's last two sets of poses, each with its simulated time
// and when it came: between them a moving model is drawn gliding from the
// one to the other over the time the last took to come, so robots move
// smoothly at the page's frame rate, one pose interval (a tenth of a second
// at Stage's default step) behind the simulator.
const motion = {};
let paintAt = 0;        // when the frame being painted is painted
let gliding = false;    // a model was drawn between two poses: draw again
const JUMP = 1.0;       // metres: a pose further than this is a jump, not a glide

function takePoses(f) {
  const now = performance.now();
  for (const [sim, poses] of Object.entries(f.poses)) {
    const time = f.times[sim];
    const m = motion[sim];
    if (m && m.last.time === time) {
      m.last.poses = poses;   // the same instant, another part of the world
    } else {
      motion[sim] = { prev: m ? m.last : null, last: { time, at: now, poses } };
    }
  }
}

// A model's pose in the world: streamed if it moves, as described if not.
function poseOf(world, id) {
  // (?still pages read no stream: nothing glides.)
  const m = motion[world.simulation];
  const last = m && m.last.poses[id];
  if (!last) {
    const live = frame && frame.poses[world.simulation];
    return live && live[id] ? live[id] : world.models[id].pose;
  }
  const before = m.prev && m.prev.poses[id];
  if (!before || Math.hypot(last[0] - before[0], last[1] - before[1]) > JUMP) return last;
  const k = (paintAt - m.last.at) / Math.max(m.last.at - m.prev.at, 1);
  if (k >= 1) return last;
  gliding = true;
  const turn = Math.atan2(Math.sin(last[2] - before[2]), Math.cos(last[2] - before[2]));
  return [before[0] + (last[0] - before[0]) * k, before[1] + (last[1] - before[1]) * k, before[2] + turn * k];
}

function fit() {
  let lo = [Infinity, Infinity], hi = [-Infinity, -Infinity];
  for (const m of maps) {
    lo = [Math.min(lo[0], m.origin[0]), Math.min(lo[1], m.origin[1])];
    hi = [Math.max(hi[0], m.origin[0] + m.width * m.resolution), Math.max(hi[1], m.origin[1] + m.height * m.resolution)];
  }
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
  const scan = frame && frame.readings[d.device];
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

// An estimate's covariance as its two-sigma ellipse.
function drawEllipse(h) {
  const [xx, yy, xy] = [h.cov[0], h.cov[1], h.cov[3]];
  const mid = (xx + yy) / 2, dev = Math.sqrt(((xx - yy) / 2) ** 2 + xy * xy);
  const [l1, l2] = [Math.max(mid + dev, 0), Math.max(mid - dev, 0)];
  const turn = 0.5 * Math.atan2(2 * xy, xx - yy);
  const [sx, sy] = toScreen(h.mean[0], h.mean[1]);
  ctx.beginPath();
  ctx.ellipse(sx, sy, Math.max(2 * Math.sqrt(l1) * view.scale, 2), Math.max(2 * Math.sqrt(l2) * view.scale, 2), -turn, 0, 2 * Math.PI);
  ctx.stroke();
  arrow(h.mean, 0.4);
}

// A pose as an arrow `len` metres long.
function arrow(p, len) {
  const [x0, y0] = toScreen(p[0], p[1]);
  const [x1, y1] = toScreen(p[0] + len * Math.cos(p[2]), p[1] + len * Math.sin(p[2]));
  ctx.beginPath();
  ctx.moveTo(x0, y0);
  ctx.lineTo(x1, y1);
  const a = Math.atan2(y1 - y0, x1 - x0);
  ctx.lineTo(x1 - 8 * Math.cos(a - 0.4), y1 - 8 * Math.sin(a - 0.4));
  ctx.moveTo(x1, y1);
  ctx.lineTo(x1 - 8 * Math.cos(a + 0.4), y1 - 8 * Math.sin(a + 0.4));
  ctx.stroke();
}

// Localizers' particles and hypotheses, planners' goals and paths.
function drawNav() {
  if (!frame || !frame.nav) return;
  // Plans under estimates: a path starts where the robot is thought to be.
  const order = n => (n.kind === "planner" ? 0 : 1);
  for (const n of Object.values(frame.nav).sort((a, b) => order(a) - order(b))) {
    ctx.lineWidth = 2;
    if (n.kind === "localize") {
      ctx.fillStyle = "rgba(200,0,200,0.5)";
      for (const p of n.particles || []) {
        const [sx, sy] = toScreen(p[0], p[1]);
        ctx.fillRect(sx - 1, sy - 1, 2, 2);
      }
      ctx.strokeStyle = "#c000c0";
      for (const h of n.hypoths || []) drawEllipse(h);
    } else if (n.kind === "planner" && n.valid) {
      ctx.strokeStyle = "#e07000";
      // The server's `path`: from the robot to the waypoint it drives to, then to the goal.
      const path = n.path || [];
      ctx.beginPath();
      path.forEach((p, k) => {
        const [sx, sy] = toScreen(p[0], p[1]);
        if (k === 0) ctx.moveTo(sx, sy); else ctx.lineTo(sx, sy);
      });
      ctx.stroke();
      const [gx, gy] = toScreen(n.goal[0], n.goal[1]);
      ctx.beginPath();
      ctx.arc(gx, gy, 6, 0, 2 * Math.PI);
      ctx.stroke();
      arrow(n.goal, 0.5);
    }
  }
  if (aim) {
    ctx.strokeStyle = tool() === "goal" ? "#e07000" : "#c000c0";
    arrow(aim.pose, 0.6);
  }
}

// The canvas as large as the page lays it out.
function size() {
  const r = canvas.getBoundingClientRect();
  if (canvas.width !== Math.round(r.width) || canvas.height !== Math.round(r.height)) {
    canvas.width = Math.round(r.width);
    canvas.height = Math.round(r.height);
  }
}

let drawn = 0, drawing_ms = 0;   // frames drawn and the time it took, for ?report
function draw() {
  const t0 = performance.now();
  paintAt = t0;
  gliding = false;
  paint();
  drawn++;
  drawing_ms += performance.now() - t0;
  if (gliding) redraw();
}

function paint() {
  size();
  if (follow) {
    for (const w of worlds) {
      const id = w.models.findIndex(m => m.name === follow);
      if (id >= 0) { const p = poseOf(w, id); view.x = p[0]; view.y = p[1]; }
    }
  }
  ctx.fillStyle = "#fff";
  ctx.fillRect(0, 0, canvas.width, canvas.height);
  // Map devices' grids under everything (north up; their origin is the
  // corner of cell (0, 0)).
  ctx.imageSmoothingEnabled = false;
  for (const m of maps) {
    if (!m.image.complete) continue;
    const [sx, sy] = toScreen(m.origin[0], m.origin[1] + m.height * m.resolution);
    ctx.drawImage(m.image, sx, sy, m.width * m.resolution * view.scale, m.height * m.resolution * view.scale);
  }
  for (const w of worlds) {
    // The still world first, then what moves, each over its parent.
    w.models.forEach((m, id) => { if (!m.moves) drawModel(w, id); });
    w.models.forEach((m, id) => { if (m.moves) drawModel(w, id); });
    for (const d of w.devices) drawScan(w, d);
  }
  drawNav();
  for (const w of worlds) {
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
  if (!worlds.length && !maps.length) parts.push("no simulator or map yet");
  if (!params.has("still")) sendBox(false);
  if (notice && Date.now() < notice.until) parts.push(notice.text);
  statusLine.textContent = parts.join(" · ") || "waiting for data…";
}

// What this page shows of the world, told to the server (at most four
// times a second) so that its frames carry only that.
const pageId = Math.random().toString(36).slice(2);
let sentBox = "", boxSentAt = 0, boxTimer = null;
function sendBox(force) {
  const [hw, hh] = [canvas.width / 2 / view.scale, canvas.height / 2 / view.scale];
  const box = [view.x - hw, view.y - hh, view.x + hw, view.y + hh].map(v => +v.toFixed(2));
  const key = JSON.stringify(box);
  if (!force && key === sentBox) return;
  const wait = 250 - (performance.now() - boxSentAt);
  if (!force && wait > 0) {
    if (!boxTimer) boxTimer = setTimeout(() => { boxTimer = null; sendBox(false); }, wait);
    return;
  }
  sentBox = key;
  boxSentAt = performance.now();
  fetch("/api/view", { method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify({ page: pageId, ns, box }) });
}

// At most ?fps frames a second (60 by default), each at the display's
// next refresh.
const maxFps = parseFloat(params.get("fps") || "60");
let drawing = false, drawnAt = -Infinity;
function redraw() {
  if (drawing) return;
  drawing = true;
  requestAnimationFrame(function tick(t) {
    if (t - drawnAt < 1000 / maxFps - 2) { requestAnimationFrame(tick); return; }
    drawing = false;
    drawnAt = t;
    draw();
  });
}

async function getJson(path) {
  const r = await fetch(path, { cache: "no-store" });
  if (!r.ok) throw new Error(`${path}: ${r.status}`);
  return r.json();
}

async function loadWorlds() {
  const all = await getJson(api("/api/world"));
  worlds = all.worlds;
  document.getElementById("namespace").textContent = all.namespace ? ` in ${all.namespace}` : "";
  // Several namespaces: a choice of which to show (the page reloads on it).
  const spaces = document.getElementById("spaces");
  spaces.hidden = all.namespaces.length < 2;
  if (!spaces.hidden && !spaceSelect.options.length) {
    spaceSelect.innerHTML = all.namespaces.map((n, k) =>
      `<option value="${k}"${k === ns ? " selected" : ""}>${n === null ? "(no namespace)" : n}</option>`).join("");
  }
  if (all.looking_only) {
    // A viewer identity: the fleet's rules drop its commands, so it offers none.
    document.getElementById("commands").hidden = true;
    const looking = document.getElementById("looking");
    looking.hidden = false;
    looking.textContent = `Looking only: this view joins the fleet as the viewer \u201c${all.looking_only}\u201d, which may not command.`;
  }
  const pictures = await Promise.all(all.maps.map(m => new Promise(done => {
    const image = new Image();
    image.onload = image.onerror = () => done({ ...m, image });
    image.src = api(`/api/map/${m.device}?v=${mapVersion}`);
  })));
  // Each robot's first map (a stack's filters serve others from it).
  const robot = m => m.device.split(":")[0];
  maps = pictures.filter((m, k) => pictures.findIndex(o => robot(o) === robot(m)) === k);
  const names = [];
  for (const w of worlds) for (const m of w.models) if (m.moves && m.parent === null) names.push(m.name);
  followSelect.innerHTML = '<option value="">(nothing)</option>' +
    names.map(n => `<option${n === follow ? " selected" : ""}>${n}</option>`).join("");
}

// The devices of one interface as a select's options, keeping the choice;
// with none, the select is hidden and the tool that needs it, `tool`, off.
function offer(select, list, iface, none, tool) {
  const keep = select.value;
  const names = list.filter(d => d.device.startsWith(iface + ":")).map(d => `${d.robot}:${d.device}`);
  select.innerHTML = (none ? '<option value="">(nothing)</option>' : "") +
    names.map(n => `<option${n === keep ? " selected" : ""}>${n}</option>`).join("");
  select.hidden = !names.length;
  if (tool) {
    const radio = document.querySelector(`input[name="tool"][value="${tool}"]`);
    radio.disabled = !names.length;
    radio.parentElement.title = names.length ? "" : `no ${iface} device is live`;
    if (radio.disabled && radio.checked) document.querySelector('input[name="tool"][value="pan"]').checked = true;
  }
}

async function loadDevices() {
  const list = await getJson(api("/api/devices"));
  deviceCount = list.length;
  offer(plannerSelect, list, "planner", false, "goal");
  offer(localizerSelect, list, "localize", false, "pose");
  offer(teleopSelect, list, "position2d", true, null);
  deviceTable.innerHTML = list.map(d => {
    const key = `${d.robot}:${d.device}`;
    return `<tr data-key="${key}"${key === chosen ? ' class="chosen"' : ""}><td class="robot">${d.robot}</td><td>${d.device}</td><td>${d.driver}</td><td class="rate"></td></tr>`;
  }).join("");
}

function onFrame(f) {
  frame = f;
  takePoses(f);
  const known = new Set(worlds.map(w => w.simulation));
  if (Object.keys(f.poses).some(s => !known.has(s)) || f.maps !== maps.length || f.map_version !== mapVersion) {
    mapVersion = f.map_version;
    loadWorlds().then(redraw, () => {});
  }
  if (f.devices !== deviceCount) loadDevices().catch(() => {});
  // Each device's updates a second, as `troupe hz` counts them.
  for (const row of deviceTable.rows) {
    const r = f.rates && f.rates[row.dataset.key];
    row.cells[3].textContent = r === undefined ? "" : `${r.toFixed(r < 10 ? 1 : 0)} Hz`;
  }
  showPanel();
  redraw();
}

deviceTable.addEventListener("click", e => {
  const row = e.target.closest("tr");
  if (!row) return;
  chosen = chosen === row.dataset.key ? "" : row.dataset.key;
  for (const r of deviceTable.rows) r.classList.toggle("chosen", r.dataset.key === chosen);
  showPanel();
});

const fmt = (v, d = 3) => (typeof v === "number" ? v.toFixed(d) : "–");

// The chosen device, as playerv shows it: a range plot, odometry and
// speeds, a power level, a map's picture, an estimate, a plan.
function showPanel() {
  if (!chosen) { panel.innerHTML = ""; return; }
  const iface = chosen.split(":")[1];
  const r = frame && frame.readings[chosen];
  const n = frame && frame.nav && frame.nav[chosen];
  if (iface === "map") {
    // A map that grows (the slam driver's) gets a new picture with each version.
    const img = panel.querySelector("img");
    if (!img || img.dataset.version !== String(mapVersion)) {
      panel.innerHTML = `<img src="${api(`/api/map/${chosen}?v=${mapVersion}`)}" data-version="${mapVersion}" alt="${chosen}">`;
    }
    return;
  }
  if (r && (r.kind === "laser" || r.kind === "ranger")) {
    let plot = panel.querySelector("canvas");
    if (!plot) { panel.innerHTML = '<canvas width="236" height="120"></canvas><div></div>'; plot = panel.querySelector("canvas"); }
    const g = plot.getContext("2d");
    const top = Math.max(...r.ranges, 0.001);
    g.clearRect(0, 0, plot.width, plot.height);
    g.strokeStyle = "#0040c0";
    g.beginPath();
    r.ranges.forEach((v, k) => {
      const x = r.ranges.length > 1 ? k * (plot.width - 1) / (r.ranges.length - 1) : plot.width / 2;
      const y = plot.height - 1 - v / top * (plot.height - 10);
      if (k === 0) g.moveTo(x, y); else g.lineTo(x, y);
    });
    g.stroke();
    panel.querySelector("div").textContent = `${r.ranges.length} ranges, ${fmt(Math.min(...r.ranges), 2)}–${fmt(top, 2)} m`;
    return;
  }
  let text = `no reading of ${chosen} yet`;
  if (r && r.kind === "position2d") {
    text = `pose ${fmt(r.pose[0])} ${fmt(r.pose[1])} m, ${fmt(r.pose[2] * 180 / Math.PI, 1)}°<br>` +
      `speed ${fmt(r.vel[0])} m/s, ${fmt(r.vel[2] * 180 / Math.PI, 1)}°/s${r.stall ? "<br><b>stalled</b>" : ""}`;
  } else if (r && r.kind === "power") {
    text = [r.valid & 8 ? `${fmt(r.percent, 1)} %` : "", r.valid & 1 ? `${fmt(r.volts, 2)} V` : "", r.charging ? "charging" : ""]
      .filter(Boolean).join(", ") || "no level given";
  } else if (n && n.kind === "localize") {
    text = (n.hypoths || []).map(h => `${fmt(h.mean[0])} ${fmt(h.mean[1])} m, ${fmt(h.mean[2] * 180 / Math.PI, 1)}° (weight ${fmt(h.weight, 2)})`).join("<br>") || "no hypothesis";
  } else if (n && n.kind === "planner") {
    const heading = n.waypoint_idx > 0 ? `, driving to waypoint ${n.waypoint_idx - 1}` : "";
    text = `goal ${fmt(n.goal[0])} ${fmt(n.goal[1])} m; ${n.done ? "arrived" : n.valid ? `${n.waypoints_count} waypoints${heading}` : "no path"}`;
  } else if (!["laser", "ranger", "sonar", "position2d", "power", "localize", "planner", "map"].includes(iface)) {
    text = `the view has no panel for ${iface} yet`;
  }
  panel.innerHTML = `<div>${text}</div>`;
}

followSelect.addEventListener("change", () => { follow = followSelect.value; redraw(); });
spaceSelect.addEventListener("change", () => {
  const next = new URLSearchParams(location.search);
  next.set("ns", spaceSelect.value);
  for (const k of ["follow", "device", "x", "y", "scale"]) next.delete(k);
  location.search = next.toString();
});

function tool() {
  return document.querySelector('input[name="tool"]:checked').value;
}

// The world point under a mouse event.
function toWorld(e) {
  const r = canvas.getBoundingClientRect();
  return [view.x + (e.clientX - r.left - canvas.width / 2) / view.scale,
          view.y - (e.clientY - r.top - canvas.height / 2) / view.scale];
}

async function order(body) {
  const r = await fetch("/api/command", { method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify({ ns, ...body }) });
  const text = await r.text();
  if (!r.ok) notice = { text: `${body.device}: ${text}`, until: Date.now() + 5000 };
  return r.ok;
}

// A goal or a pose: pressed where it is, dragged the way it faces.
let aim = null;
let drag = null;
canvas.addEventListener("mousedown", e => {
  if (tool() === "pan") {
    drag = [e.clientX, e.clientY];
    canvas.classList.add("dragging");
  } else {
    const at = toWorld(e);
    aim = { from: at, pose: [at[0], at[1], 0] };
  }
});
window.addEventListener("mouseup", e => {
  drag = null;
  canvas.classList.remove("dragging");
  if (!aim) return;
  const p = aim.pose;
  aim = null;
  if (tool() === "goal" && plannerSelect.value) order({ device: plannerSelect.value, goal: p });
  if (tool() === "pose" && localizerSelect.value) order({ device: localizerSelect.value, pose: p });
  redraw();
});
window.addEventListener("mousemove", e => {
  if (aim) {
    const at = toWorld(e);
    const [dx, dy] = [at[0] - aim.from[0], at[1] - aim.from[1]];
    if (Math.hypot(dx, dy) > 0.05) aim.pose[2] = Math.atan2(dy, dx);
    redraw();
    return;
  }
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

// Teleop: the keys held give speeds, sent ten times a second while held
// and a stop once all are let go.
const held = new Set();
const KEYS = { ArrowUp: "f", w: "f", ArrowDown: "b", s: "b", ArrowLeft: "l", a: "l", ArrowRight: "r", d: "r" };
function speeds() {
  const v = (held.has("f") ? 0.4 : 0) - (held.has("b") ? 0.4 : 0);
  const w = (held.has("l") ? 0.8 : 0) - (held.has("r") ? 0.8 : 0);
  return [v, 0, w];
}
window.addEventListener("keydown", e => {
  const k = KEYS[e.key];
  if (!k || !teleopSelect.value || e.target.tagName === "SELECT") return;
  e.preventDefault();
  held.add(k);
});
window.addEventListener("keyup", e => {
  const k = KEYS[e.key];
  if (!k || !held.delete(k) || !teleopSelect.value) return;
  if (!held.size) order({ device: teleopSelect.value, vel: [0, 0, 0] });
});
setInterval(() => {
  if (held.size && teleopSelect.value) order({ device: teleopSelect.value, vel: speeds() });
}, 100);

(async () => {
  try {
    await loadWorlds();
    await loadDevices();
    frame = await getJson(api("/api/frame"));
  } catch (e) {
    statusLine.textContent = `cannot reach the view server: ${e.message}`;
  }
  size();
  if (!view.fixed) fit();
  draw();
  showPanel();
  document.body.dataset.ready = "1";
  // ?report: say how many frames a second this page draws, every 2 s.
  if (params.has("report")) {
    const page = Math.random().toString(36).slice(2);
    let [then, before, spent] = [performance.now(), drawn, drawing_ms];
    setInterval(() => {
      const now = performance.now();
      const fps = (drawn - before) * 1000 / (now - then);
      const ms = (drawing_ms - spent) / Math.max(drawn - before, 1);
      [then, before, spent] = [now, drawn, drawing_ms];
      fetch("/api/report", { method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify({ page, fps, ms }) });
    }, 2000);
  }
  // ?still: this moment only (for a screenshot), no stream.
  if (params.has("still")) return;
  const events = new EventSource(api(`/api/stream?page=${pageId}`));
  events.onopen = () => sendBox(true);
  events.onmessage = m => onFrame(JSON.parse(m.data));
  events.onerror = () => { statusLine.textContent = "reconnecting to the view server…"; };
})();
