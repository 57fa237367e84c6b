// NUSense dashboard: readings from the WebSocket, frames from /api/v1/frame.jpg, status and controls through the
// API. With --token, the page was opened once as /?token=...: the daemon keeps the token in a cookie, which every
// request here carries by itself.
"use strict";

const API = "/api/v1";
const SIDES = ["top", "right", "bottom", "left"];
const HISTORY_S = 20;
const READINGS_KEPT = 120; // frame ids the overlay may still ask for
const ARROW_GAIN = 4; // shear arrows drawn this many times their length, so sub-pixel shear shows
const COLOURS = { lattice: "rgb(40, 255, 90)", shear: "rgb(0, 200, 255)", contact: "rgb(255, 0, 255)" };

const $ = (id) => document.getElementById(id);
const fmt = (v, digits) => (typeof v === "number" && isFinite(v) ? v.toFixed(digits) : "–");

const readings = new Map(); // frame_id -> reading message
const forceHistory = []; // [time_s, force_n]
let latest = null;
let drawPending = false;
let shown = { frameId: null, width: 0, height: 0, drawnFor: null };
let connectionProblem = "connecting to the daemon…";
let statusProblems = [];

function connect() {
  const scheme = location.protocol === "https:" ? "wss:" : "ws:";
  const ws = new WebSocket(scheme + "//" + location.host + API + "/stream");
  ws.onopen = () => {
    connectionProblem = null;
    $("connection").textContent = "live";
    $("connection").className = "badge live";
    showProblems();
  };
  ws.onclose = (event) => {
    connectionProblem = "connection to the daemon lost" + (event.reason ? " (" + event.reason + ")" : "") + "; retrying";
    $("connection").textContent = "disconnected, retrying";
    $("connection").className = "badge down";
    showProblems();
    setTimeout(connect, 1000);
  };
  ws.onmessage = (event) => {
    const reading = JSON.parse(event.data);
    latest = reading;
    readings.set(reading.frame_id, reading);
    while (readings.size > READINGS_KEPT) readings.delete(readings.keys().next().value);
    const est = reading.estimate;
    const now_s = reading.capture_time_us / 1e6;
    if (est) forceHistory.push([now_s, est.force_n]);
    while (forceHistory.length && forceHistory[0][0] < now_s - HISTORY_S) forceHistory.shift();
    if (reading.frame_id === shown.frameId) drawOverlay();
    if (!drawPending) { drawPending = true; requestAnimationFrame(draw); }
  };
}

function draw() {
  drawPending = false;
  const r = latest;
  if (!r) return;
  const est = r.estimate;
  $("frame-id").textContent = r.frame_id + (r.reference_frame_id != null ? " (rest frame " + r.reference_frame_id + ")" : "");
  $("latency").textContent = fmt(r.latency_ms, 1) + " ms";
  $("estimate-error").textContent = r.error ? r.error : "ok";
  $("estimate-error").className = r.error ? "error" : "";
  if (est) {
    $("force").textContent = fmt(est.force_n, 3);
    $("contact").textContent = est.contact ? "yes" : "no";
    $("contact-mm").textContent = est.contact_mm ? fmt(est.contact_mm[0], 1) + ", " + fmt(est.contact_mm[1], 1) + " mm" : "–";
    $("edge").textContent = est.edge_angle_deg != null ? fmt(est.edge_angle_deg, 1) + "° (confidence " + fmt(est.edge_confidence, 2) + ")" : "none";
    $("gamma").textContent = fmt(est.gamma, 4);
    $("points").textContent = est.points_detected + " / " + est.points_expected;
  } else {
    for (const id of ["force", "contact", "contact-mm", "edge", "gamma", "points"]) $(id).textContent = "–";
  }
  drawLeds(r.led);
  drawHeatmap(est);
  drawForceChart();
}

// --- camera and overlay -------------------------------------------------------------------------------------

async function refreshFrame() {
  try {
    const response = await fetch(API + "/frame.jpg", { cache: "no-store" });
    if (response.ok) {
      const frameId = Number(response.headers.get("x-nusense-frame-id"));
      const url = URL.createObjectURL(await response.blob());
      const img = $("frame");
      await new Promise((resolve) => {
        img.onload = img.onerror = resolve;
        img.src = url;
      });
      URL.revokeObjectURL(url);
      shown = { frameId, width: img.naturalWidth, height: img.naturalHeight, drawnFor: null };
      $("shown-frame").textContent = frameId;
      drawOverlay();
    }
  } catch (e) { /* the daemon is restarting; the connection badge says so */ }
  setTimeout(refreshFrame, 150);
}

function cornerIndex(v) {
  const idx = v.index;
  if (Array.isArray(idx)) return [idx[0], idx[1]];
  if (idx && typeof idx === "object") return [idx.row, idx.col];
  return null;
}

function contactsOf(est) {
  if (Array.isArray(est.contacts) && est.contacts.length) return est.contacts.map((c) => c.centre_px);
  return est.contact && est.contact_px ? [est.contact_px] : [];
}

// Draws the lattice, shear and contacts of the reading of the frame on screen (never another frame's), in the
// frame's own pixels: the canvas has the picture's size and is scaled with it.
function drawOverlay() {
  const canvas = $("overlay");
  const reading = readings.get(shown.frameId);
  if (!shown.width) return;
  if (canvas.width !== shown.width || canvas.height !== shown.height) {
    canvas.width = shown.width;
    canvas.height = shown.height;
  }
  const ctx = canvas.getContext("2d");
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  canvas.dataset.frameId = "";
  if (!reading || !reading.estimate) return;
  const est = reading.estimate;
  const px = canvas.width / Math.max(1, canvas.clientWidth); // one screen pixel, in frame pixels
  const corners = new Map();
  for (const v of est.shear_field || []) {
    const rc = cornerIndex(v);
    if (rc && v.valid && v.current_px) corners.set(rc[0] + "," + rc[1], v.current_px);
  }
  ctx.strokeStyle = COLOURS.lattice;
  ctx.lineWidth = 1.5 * px;
  ctx.beginPath();
  for (const [key, p] of corners) {
    const [row, col] = key.split(",").map(Number);
    for (const q of [corners.get(row + 1 + "," + col), corners.get(row + "," + (col + 1))]) {
      if (q) { ctx.moveTo(p[0], p[1]); ctx.lineTo(q[0], q[1]); }
    }
  }
  ctx.stroke();
  ctx.strokeStyle = COLOURS.shear;
  ctx.lineWidth = 2 * px;
  ctx.beginPath();
  for (const v of est.shear_field || []) {
    if (!v.valid || !v.reference_px || !v.current_px) continue;
    const [rx, ry] = v.reference_px;
    ctx.moveTo(rx, ry);
    ctx.lineTo(rx + ARROW_GAIN * (v.current_px[0] - rx), ry + ARROW_GAIN * (v.current_px[1] - ry));
  }
  ctx.stroke();
  ctx.strokeStyle = COLOURS.contact;
  ctx.lineWidth = 3 * px;
  for (const [cx, cy] of contactsOf(est)) {
    const r = 14 * px;
    ctx.beginPath();
    ctx.arc(cx, cy, r, 0, 2 * Math.PI);
    ctx.moveTo(cx - 1.6 * r, cy); ctx.lineTo(cx + 1.6 * r, cy);
    ctx.moveTo(cx, cy - 1.6 * r); ctx.lineTo(cx, cy + 1.6 * r);
    ctx.stroke();
  }
  canvas.dataset.frameId = String(shown.frameId);
}

// --- plots ----------------------------------------------------------------------------------------------------

// 1, 2 or 5 times a power of ten, the smallest not below `value`.
function niceCeil(value) {
  const power = Math.pow(10, Math.floor(Math.log10(value)));
  for (const m of [1, 2, 5, 10]) if (m * power >= value) return m * power;
  return 10 * power;
}

function drawForceChart() {
  const canvas = $("force-chart");
  const ctx = canvas.getContext("2d");
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  const left = 44, right = 10, top = 10, bottom = 26;
  const w = canvas.width - left - right, h = canvas.height - top - bottom;
  let fMax = 0;
  for (const [, f] of forceHistory) fMax = Math.max(fMax, f);
  // At least 1 N full scale, so sensor noise at rest is not blown up to fill the plot.
  const step = niceCeil(Math.max(1, fMax * 1.15) / 4);
  const yMax = step * Math.max(1, Math.ceil(Math.max(1, fMax * 1.15) / step));
  const tEnd = forceHistory.length ? forceHistory[forceHistory.length - 1][0] : 0;
  const x = (t) => left + (1 - (tEnd - t) / HISTORY_S) * w;
  const y = (f) => top + h - (Math.max(0, f) / yMax) * h;
  ctx.font = "11px system-ui, sans-serif";
  ctx.strokeStyle = "#333"; ctx.fillStyle = "#aaa"; ctx.lineWidth = 1;
  ctx.textAlign = "right"; ctx.textBaseline = "middle";
  for (let f = 0; f <= yMax + 1e-9; f += step) {
    ctx.beginPath(); ctx.moveTo(left, y(f)); ctx.lineTo(left + w, y(f)); ctx.stroke();
    ctx.fillText(f.toFixed(step < 1 ? 1 : 0) + " N", left - 4, y(f));
  }
  ctx.textAlign = "center"; ctx.textBaseline = "top";
  for (let ago = 0; ago <= HISTORY_S; ago += 5) {
    const xx = left + (1 - ago / HISTORY_S) * w;
    ctx.beginPath(); ctx.moveTo(xx, top); ctx.lineTo(xx, top + h); ctx.stroke();
    ctx.fillText(ago === 0 ? "now" : "-" + ago + " s", xx, top + h + 6);
  }
  if (forceHistory.length < 2) return;
  ctx.strokeStyle = "#4fc3f7"; ctx.lineWidth = 2;
  ctx.beginPath();
  forceHistory.forEach(([t, f], i) => (i ? ctx.lineTo(x(t), y(f)) : ctx.moveTo(x(t), y(f))));
  ctx.stroke();
}

function drawHeatmap(est) {
  const canvas = $("heatmap");
  const ctx = canvas.getContext("2d");
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  if (!est || !est.shear_field || !est.shear_field.length) return;
  let rows = 0, cols = 0, maxMag = 0.05;
  const cells = [];
  for (const v of est.shear_field) {
    const rc = cornerIndex(v);
    if (!rc) continue;
    rows = Math.max(rows, rc[0] + 1);
    cols = Math.max(cols, rc[1] + 1);
    const d = v.displacement_mm;
    const mag = v.valid && d ? Math.hypot(d[0], d[1]) : null;
    if (mag != null) maxMag = Math.max(maxMag, mag);
    cells.push([rc[0], rc[1], mag, d]);
  }
  const cw = canvas.width / cols, ch = canvas.height / rows;
  for (const [row, col, mag, d] of cells) {
    if (mag == null) { ctx.fillStyle = "#333"; }
    else {
      const t = Math.min(1, mag / maxMag);
      ctx.fillStyle = "hsl(" + (240 - 240 * t) + ", 90%, " + (25 + 35 * t) + "%)";
    }
    ctx.fillRect(col * cw, row * ch, cw + 0.5, ch + 0.5);
    if (mag != null && mag > 0.02 * maxMag) {
      const cx = (col + 0.5) * cw, cy = (row + 0.5) * ch, s = 0.45 * Math.min(cw, ch) / maxMag;
      ctx.strokeStyle = "#fff";
      ctx.beginPath(); ctx.moveTo(cx, cy); ctx.lineTo(cx + d[0] * s, cy + d[1] * s); ctx.stroke();
    }
  }
  ctx.fillStyle = "#fff";
  ctx.fillText("max " + maxMag.toFixed(3) + " mm", 6, canvas.height - 6);
}

// --- LEDs, status, problems -------------------------------------------------------------------------------------

function drawLeds(led) {
  const body = $("led-table").tBodies[0];
  body.textContent = "";
  SIDES.forEach((side, i) => {
    const row = body.insertRow();
    const faults = led ? led.faults[i] : [];
    const cells = led
      ? [side, led.setpoint_ma[i] + " mA", fmt(led.measured_ma[i], 1) + " mA", led.enabled[i] ? "on" : "off",
         faults.length ? faults.join(", ").replace(/_/g, " ") : "none"]
      : [side, "–", "–", "–", "–"];
    for (const text of cells) row.insertCell().textContent = text;
    if (faults.length) row.cells[4].className = "fault";
  });
}

function describeBoard(board, serial) {
  if (board.kind === "none") return "no LED board: the LEDs are not the daemon's to control";
  const link = board.link || {};
  const name = (board.kind === "virtual" ? "virtual board" : "LED board") + (serial ? " " + serial : "") +
    (link.port ? " on " + link.port : "");
  if (!board.connected) return name + ": not connected" + (link.last_error ? " (" + link.last_error + ")" : "");
  const t = link.telemetry;
  return name + ", connected" + (t ? "; " + fmt(t.temperature_c, 1) + " °C, supply " + fmt(t.supply_mv / 1000, 2) + " V" : "");
}

async function refreshStatus() {
  try {
    const response = await fetch(API + "/status", { cache: "no-store" });
    const status = await response.json();
    if (!response.ok) throw new Error(status.error || response.statusText);
    const cam = status.camera;
    $("source").textContent = (status.simulator ? "simulator: " : cam.kind + ": ") + cam.name + " " + cam.width + "×" + cam.height +
      " — " + status.pipeline.frames_dropped + " frames dropped";
    $("board-state").textContent = describeBoard(status.board, status.serial_number);
    $("recordings-dir").textContent = status.recordings_dir;
    const rec = status.pipeline.recording;
    $("record").textContent = rec ? "Stop recording" : "Start recording";
    $("record").dataset.recording = rec ? "1" : "";
    const failure = status.pipeline.recording_failure;
    if (rec) {
      $("record-state").textContent = "recording " + rec.path + ": " + rec.frames + " frames, " + rec.readings +
        " readings" + (rec.dropped ? ", " + rec.dropped + " dropped (the disk is behind)" : "");
      $("record-state").className = "";
    } else if (failure) {
      $("record-state").textContent = (failure.disk_full ? "stopped: the disk is full — " : "stopped: ") + failure.error;
      $("record-state").className = "error";
    }
    statusProblems = status.problems;
  } catch (e) {
    statusProblems = ["status unavailable: " + e.message];
  }
  showProblems();
  setTimeout(refreshStatus, 1000);
}

function showProblems() {
  const list = $("problems");
  const problems = (connectionProblem ? [connectionProblem] : []).concat(statusProblems);
  list.textContent = "";
  for (const text of problems) list.appendChild(document.createElement("li")).textContent = text;
  list.hidden = problems.length === 0;
}

async function send(method, path, body) {
  const response = await fetch(API + path, {
    method, headers: { "content-type": "application/json" }, body: body === undefined ? undefined : JSON.stringify(body),
  });
  const text = await response.text();
  let json = {};
  try { json = JSON.parse(text); } catch (e) { json = { error: text }; }
  if (!response.ok) throw new Error(json.error || response.statusText);
  return json;
}

$("led-form").addEventListener("submit", async (event) => {
  event.preventDefault();
  const body = {};
  for (const side of SIDES) {
    const value = event.target.elements[side].value;
    if (value !== "") body[side] = Number(value);
  }
  const message = $("led-message");
  try {
    await send("PUT", "/led", body);
    message.textContent = "set"; message.className = "";
  } catch (e) {
    message.textContent = e.message; message.className = "error";
  }
});

$("tare").addEventListener("click", () => send("POST", "/tare").catch(() => {}));

$("record").addEventListener("click", async () => {
  const state = $("record-state");
  try {
    const recording = $("record").dataset.recording === "1";
    const name = $("record-name").value.trim();
    const body = recording ? { action: "stop" } : Object.assign({ action: "start" }, name ? { path: name } : {});
    const result = await send("POST", "/record", body);
    state.textContent = recording ? "saved " + result.recorded.path + " (" + result.recorded.frames + " frames)" : "recording " + result.recording.file;
    state.className = "";
  } catch (e) { state.textContent = e.message; state.className = "error"; }
});

drawLeds(null);
drawForceChart();
showProblems();
connect();
refreshFrame();
refreshStatus();
