// NUSense dashboard: readings from the WebSocket, frames from /api/frame.jpg, controls through the API.
"use strict";

const token = new URLSearchParams(location.search).get("token");
function api(path) {
  if (!token) return path;
  return path + (path.includes("?") ? "&" : "?") + "token=" + encodeURIComponent(token);
}
const $ = (id) => document.getElementById(id);
const fmt = (v, digits) => (typeof v === "number" && isFinite(v) ? v.toFixed(digits) : "–");

const forceHistory = []; // [time_s, force_n]
const HISTORY_S = 20;
let latest = null;
let drawPending = false;
let imageSize = null;

function connect() {
  const scheme = location.protocol === "https:" ? "wss:" : "ws:";
  const ws = new WebSocket(scheme + "//" + location.host + api("/api/v1/stream"));
  ws.onopen = () => { $("connection").textContent = "live"; $("connection").className = "badge live"; };
  ws.onclose = () => {
    $("connection").textContent = "disconnected, retrying";
    $("connection").className = "badge down";
    setTimeout(connect, 1000);
  };
  ws.onmessage = (event) => {
    latest = JSON.parse(event.data);
    const est = latest.estimate;
    if (est) forceHistory.push([latest.capture_time_us / 1e6, est.force_n]);
    const cutoff = latest.capture_time_us / 1e6 - HISTORY_S;
    while (forceHistory.length && forceHistory[0][0] < cutoff) forceHistory.shift();
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
  if (r.led) {
    $("led-measured").textContent = "measured: " + ["Top", "Right", "Bottom", "Left"]
      .map((side, i) => side + " " + fmt(r.led.measured_ma[i], 0) + " mA").join(", ") + (r.led.any_fault ? " — FAULT" : "");
  }
  if (est) {
    $("force").textContent = fmt(est.force_n, 3);
    $("contact").textContent = est.contact ? "yes" : "no";
    $("contact-mm").textContent = est.contact_mm ? fmt(est.contact_mm[0], 1) + ", " + fmt(est.contact_mm[1], 1) + " mm" : "–";
    $("edge").textContent = est.edge_angle_deg != null ? fmt(est.edge_angle_deg, 1) + "° (confidence " + fmt(est.edge_confidence, 2) + ")" : "none";
    $("gamma").textContent = fmt(est.gamma, 4);
    $("points").textContent = est.points_detected + " / " + est.points_expected;
  } else {
    $("force").textContent = "–";
    $("contact").textContent = "–";
  }
  drawHeatmap(est);
  drawForceChart();
  drawContactMarker(est);
}

function cornerIndex(v) {
  const idx = v.index;
  if (Array.isArray(idx)) return [idx[0], idx[1]];
  if (idx && typeof idx === "object") return [idx.row, idx.col];
  return null;
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

function drawForceChart() {
  const canvas = $("force-chart");
  const ctx = canvas.getContext("2d");
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  if (forceHistory.length < 2) return;
  const tEnd = forceHistory[forceHistory.length - 1][0], tStart = tEnd - HISTORY_S;
  let fMax = 0.5;
  for (const [, f] of forceHistory) fMax = Math.max(fMax, f);
  const x = (t) => ((t - tStart) / HISTORY_S) * canvas.width;
  const y = (f) => canvas.height - 10 - (f / fMax) * (canvas.height - 20);
  ctx.strokeStyle = "#4fc3f7";
  ctx.beginPath();
  forceHistory.forEach(([t, f], i) => (i ? ctx.lineTo(x(t), y(f)) : ctx.moveTo(x(t), y(f))));
  ctx.stroke();
  ctx.fillStyle = "#aaa";
  ctx.fillText(fMax.toFixed(2) + " N", 4, 12);
  ctx.fillText("0", 4, canvas.height - 2);
}

function drawContactMarker(est) {
  const canvas = $("contact-layer");
  const img = $("frame");
  canvas.width = img.clientWidth; canvas.height = img.clientHeight;
  const ctx = canvas.getContext("2d");
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  if (!est || !est.contact || !est.contact_px || !imageSize) return;
  const sx = canvas.width / imageSize[0], sy = canvas.height / imageSize[1];
  const cx = est.contact_px[0] * sx, cy = est.contact_px[1] * sy;
  ctx.strokeStyle = "#00e5ff"; ctx.lineWidth = 3;
  ctx.beginPath(); ctx.arc(cx, cy, 14, 0, 2 * Math.PI); ctx.stroke();
  ctx.beginPath(); ctx.moveTo(cx - 20, cy); ctx.lineTo(cx + 20, cy); ctx.moveTo(cx, cy - 20); ctx.lineTo(cx, cy + 20); ctx.stroke();
}

async function refreshFrame() {
  try {
    const response = await fetch(api("/api/v1/frame.jpg?overlay=1"), { cache: "no-store" });
    if (response.ok) {
      const url = URL.createObjectURL(await response.blob());
      const img = $("frame");
      img.onload = () => { imageSize = [img.naturalWidth, img.naturalHeight]; URL.revokeObjectURL(url); };
      img.src = url;
    }
  } catch (e) { /* the daemon is restarting; the next attempt will tell */ }
  setTimeout(refreshFrame, 200);
}

async function refreshStatus() {
  try {
    const status = await (await fetch(api("/api/v1/status"))).json();
    const cam = status.camera;
    $("source").textContent = (status.simulator ? "simulator: " : cam.kind + ": ") + cam.name + " " + cam.width + "×" + cam.height +
      " — dropped " + status.pipeline.frames_dropped + " frames";
    const rec = status.pipeline.recording;
    $("record").textContent = rec ? "Stop recording" : "Start recording";
    $("record").dataset.recording = rec ? "1" : "";
    if (rec) $("record-state").textContent = "recording " + rec.path + ": " + rec.frames + " frames";
  } catch (e) { /* shown by the connection badge */ }
  setTimeout(refreshStatus, 1000);
}

async function send(method, path, body) {
  const response = await fetch(api(path), {
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
  for (const side of ["top", "right", "bottom", "left"]) {
    const value = event.target.elements[side].value;
    if (value !== "") body[side] = Number(value);
  }
  const message = $("led-message");
  try {
    await send("PUT", "/api/v1/led", body);
    message.textContent = "set"; message.className = "";
  } catch (e) {
    message.textContent = e.message; message.className = "error";
  }
});

$("tare").addEventListener("click", () => send("POST", "/api/v1/tare").catch(() => {}));

$("record").addEventListener("click", async () => {
  const state = $("record-state");
  try {
    const recording = $("record").dataset.recording === "1";
    const result = await send("POST", "/api/v1/record", { action: recording ? "stop" : "start" });
    state.textContent = recording ? "saved " + result.recorded.path + " (" + result.recorded.frames + " frames)" : "recording " + result.recording.file;
    state.className = "";
  } catch (e) { state.textContent = e.message; state.className = "error"; }
});

connect();
refreshFrame();
refreshStatus();
