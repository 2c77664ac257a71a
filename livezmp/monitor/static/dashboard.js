// livezmp dashboard: draws what the monitor's WebSocket feed sends (see dashboard.py).
"use strict";

const PLOT_SECONDS = 10;
const TRAIL_SECONDS = 1;
const COLORS = {
  grid: "#1d2630", axis: "#33414f", text: "#8795a3", ok: "#3ecf8e", bad: "#ff5b5b", warn: "#ffb84d",
  left: "#5aa9ff", right: "#ff9f43", com: "#ffe066", cop: "#c77dff", poly: "rgba(62,207,142,0.22)", band: "rgba(62,207,142,0.14)",
};

const state = { frame: null, points: [], alarms: [], status: null, hello: null, dirty: true, view: null, messages: 0 };
window.livezmp = state; // for inspection from the browser console and tests

const $ = (id) => document.getElementById(id);
const fmt = (v, digits = 1, scale = 1) => (v === null || v === undefined ? "–" : (v * scale).toFixed(digits));

function connect() {
  const token = new URLSearchParams(location.search).get("token");
  const proto = location.protocol === "https:" ? "wss:" : "ws:";
  const ws = new WebSocket(`${proto}//${location.host}/ws` + (token ? `?token=${encodeURIComponent(token)}` : ""));
  ws.onopen = () => { $("conn").classList.add("on"); $("conn").querySelector("span").textContent = "live"; };
  ws.onclose = () => {
    $("conn").classList.remove("on");
    $("conn").querySelector("span").textContent = "offline";
    setTimeout(connect, 1000);
  };
  ws.onmessage = (ev) => receive(JSON.parse(ev.data));
}

function receive(msg) {
  state.messages += 1;
  if (msg.type === "hello") {
    state.hello = msg;
    $("source").textContent = `${msg.source} · ${msg.body} · alarm after ${Math.round(msg.alarm_after * 1000)} ms`;
    return;
  }
  state.status = msg.status;
  if (msg.frame) state.frame = msg.frame;
  for (const p of msg.points) state.points.push(p);
  if (state.points.length) {
    const tEnd = state.points[state.points.length - 1][1];
    let drop = 0;
    while (drop < state.points.length && state.points[drop][1] < tEnd - PLOT_SECONDS) drop++;
    if (drop) state.points.splice(0, drop);
  }
  for (const a of msg.alarms) state.alarms.unshift(a);
  state.alarms.length = Math.min(state.alarms.length, 100);
  if (msg.alarms.length) renderAlarms();
  renderStatus();
  state.dirty = true;
}

function renderStatus() {
  const s = state.status, f = state.frame;
  const margin = $("margin");
  margin.textContent = f && f.margin !== null ? (f.margin * 1000).toFixed(0) : "–";
  margin.className = f && f.margin !== null ? (f.margin >= 0 ? "good" : "bad") : "";
  $("support").textContent = f ? f.support : "–";
  $("zmp-readout").textContent = f && f.zmp ? `${f.zmp[0].toFixed(3)}, ${f.zmp[1].toFixed(3)}` : "–";
  $("cop-readout").textContent = f && f.cop ? `${f.cop[0].toFixed(3)}, ${f.cop[1].toFixed(3)}` : "–";
  $("cop-error").textContent = f && f.cop && f.zmp
    ? (1000 * Math.hypot(f.zmp[0] - f.cop[0], f.zmp[1] - f.cop[1])).toFixed(0) : "–";
  $("oos").textContent = `${s.out_of_support} (${fmt(s.out_fraction, 1, 100)} %)`;
  $("fps").textContent = `${fmt(s.input_fps, 1)} Hz`;
  $("frames").textContent = `${s.inputs} / ${s.results}`;
  $("cadence").textContent = s.cadence === null ? "–" : `${s.cadence.toFixed(0)} /min`;
  $("dropped").textContent = `${s.dropped} (lost ${s.lost})`;
  $("delay").textContent = s.lag_ms === null ? "–" : `${s.lag_ms.toFixed(0)} ms`;
  $("recording").textContent = s.recording || "off";
  const badge = $("badge"), banner = $("banner");
  if (s.alarm_active) {
    badge.className = "badge alarm"; badge.textContent = "ALARM";
    banner.hidden = false;
    banner.textContent = `ALARM — ZMP out of support since t = ${s.alarm_since.toFixed(2)} s`;
  } else {
    banner.hidden = true;
    if (!f || f.inside === null) { badge.className = "badge idle"; badge.textContent = f ? "NO SUPPORT" : "NO DATA"; }
    else if (f.inside) { badge.className = "badge ok"; badge.textContent = "IN SUPPORT"; }
    else { badge.className = "badge out"; badge.textContent = "OUT OF SUPPORT"; }
  }
}

function renderAlarms() {
  const list = $("alarm-list");
  list.replaceChildren(...state.alarms.map((a) => {
    const li = document.createElement("li");
    li.className = a.event;
    const time = document.createElement("time");
    time.textContent = `t=${a.t.toFixed(2)} s`;
    li.append(time, a.message);
    return li;
  }));
  const raised = state.alarms.filter((a) => a.event === "raised").length;
  $("alarm-count").textContent = raised ? `${raised} raised` : "none";
}

function fitCanvas(c) {
  const r = window.devicePixelRatio || 1, w = Math.round(c.clientWidth * r), h = Math.round(c.clientHeight * r);
  if (c.width !== w || c.height !== h) { c.width = w; c.height = h; }
  const g = c.getContext("2d");
  g.setTransform(r, 0, 0, r, 0, 0);
  return [g, c.clientWidth, c.clientHeight];
}

function polyPath(g, pts, tx) {
  g.beginPath();
  pts.forEach((p, i) => { const [x, y] = tx(p); if (i) g.lineTo(x, y); else g.moveTo(x, y); });
  g.closePath();
}

function drawTop() {
  const [g, w, h] = fitCanvas($("top"));
  g.clearRect(0, 0, w, h);
  const f = state.frame;
  if (!f) { g.fillStyle = COLORS.text; g.fillText("waiting for frames…", 12, 20); return; }
  // frame both feet, the CoM and the ZMP; zoom and pan smoothly (no jumps while walking)
  const sole = f.soles.left || f.soles.right;
  const soleLen = sole ? Math.hypot(sole[1][0] - sole[0][0], sole[1][1] - sole[0][1]) : 0.25;
  const pts = [...(f.soles.left || []), ...(f.soles.right || []), ...(f.com ? [f.com] : []), ...(f.zmp ? [f.zmp] : [])];
  const xs = pts.map((p) => p[0]), ys = pts.map((p) => p[1]);
  const [x0, x1, y0, y1] = [Math.min(...xs), Math.max(...xs), Math.min(...ys), Math.max(...ys)];
  const want = Math.min(3.0, Math.max(0.4, 4 * soleLen, 1.3 * Math.max(x1 - x0, y1 - y0)));
  const cx = (x0 + x1) / 2, cy = (y0 + y1) / 2;
  if (!state.view || Math.hypot(state.view[0] - cx, state.view[1] - cy) > state.view[2]) state.view = [cx, cy, want];
  const v = state.view;
  state.view = [v[0] + 0.5 * (cx - v[0]), v[1] + 0.5 * (cy - v[1]), v[2] + 0.1 * (want - v[2])];
  const span = state.view[2]; // metres across the canvas
  const s = Math.min(w, h) / span, [vx, vy] = state.view;
  const tx = (p) => [w / 2 + (p[0] - vx) * s, h / 2 - (p[1] - vy) * s];
  // grid every 0.1 m, labelled every 0.5 m
  g.lineWidth = 1;
  g.font = "11px system-ui";
  for (let k = Math.floor((vx - span) * 10); k <= (vx + span) * 10; k++) {
    const [x] = tx([k / 10, 0]);
    g.strokeStyle = k % 5 ? COLORS.grid : COLORS.axis;
    g.beginPath(); g.moveTo(x, 0); g.lineTo(x, h); g.stroke();
    if (k % 5 === 0) { g.fillStyle = COLORS.text; g.fillText(`x ${(k / 10).toFixed(1)}`, x + 3, h - 6); }
  }
  for (let k = Math.floor((vy - span) * 10); k <= (vy + span) * 10; k++) {
    const [, y] = tx([0, k / 10]);
    g.strokeStyle = k % 5 ? COLORS.grid : COLORS.axis;
    g.beginPath(); g.moveTo(0, y); g.lineTo(w, y); g.stroke();
    if (k % 5 === 0) { g.fillStyle = COLORS.text; g.fillText(`y ${(k / 10).toFixed(1)}`, 4, y - 3); }
  }
  if (f.polygon.length) {
    polyPath(g, f.polygon, tx);
    g.fillStyle = COLORS.poly; g.fill();
    g.strokeStyle = COLORS.ok; g.lineWidth = 2; g.stroke();
  }
  for (const side of ["left", "right"]) {
    if (!f.soles[side]) continue;
    const stance = f.support === side || f.support === "double";
    polyPath(g, f.soles[side], tx);
    g.setLineDash(stance ? [] : [5, 4]);
    g.strokeStyle = COLORS[side]; g.lineWidth = stance ? 2.5 : 1.5; g.stroke();
    g.setLineDash([]);
  }
  // trail of the last second
  const tEnd = f.t, trail = state.points.filter((p) => p[2] !== null && p[1] > tEnd - TRAIL_SECONDS);
  for (let i = 1; i < trail.length; i++) {
    const a = tx([trail[i - 1][2], trail[i - 1][3]]), b = tx([trail[i][2], trail[i][3]]);
    g.strokeStyle = `rgba(220,227,234,${(0.1 + 0.6 * i / trail.length).toFixed(2)})`;
    g.lineWidth = 1.5;
    g.beginPath(); g.moveTo(...a); g.lineTo(...b); g.stroke();
  }
  if (f.zmp) {
    const [x, y] = tx(f.zmp);
    if (f.clamped && !f.inside) {
      const [qx, qy] = tx(f.clamped);
      g.strokeStyle = COLORS.bad; g.setLineDash([4, 3]); g.lineWidth = 1.5;
      g.beginPath(); g.moveTo(x, y); g.lineTo(qx, qy); g.stroke(); g.setLineDash([]);
      g.strokeStyle = "#fff"; g.lineWidth = 2;
      g.beginPath(); g.arc(qx, qy, 7, 0, 2 * Math.PI); g.stroke();
    }
    g.fillStyle = f.inside === false ? COLORS.bad : COLORS.ok;
    g.beginPath(); g.arc(x, y, 7, 0, 2 * Math.PI); g.fill();
    g.strokeStyle = "#0b1015"; g.lineWidth = 2; g.stroke();
  }
  if (f.cop) { // the plates' measured CoP: a square, beside the computed ZMP's disc
    const [x, y] = tx(f.cop);
    g.fillStyle = COLORS.cop; g.fillRect(x - 5, y - 5, 10, 10);
    g.strokeStyle = "#0b1015"; g.lineWidth = 1.5; g.strokeRect(x - 5, y - 5, 10, 10);
  }
  if (f.com) { // on top: the CoM projection often sits close to the ZMP
    const [x, y] = tx(f.com);
    g.beginPath(); g.moveTo(x, y - 6); g.lineTo(x + 6, y); g.lineTo(x, y + 6); g.lineTo(x - 6, y); g.closePath();
    g.fillStyle = COLORS.com; g.fill();
    g.strokeStyle = "#0b1015"; g.lineWidth = 1.5; g.stroke();
  }
  // scale bar
  const bar = span > 1.2 ? 0.5 : 0.1;
  g.strokeStyle = COLORS.text; g.lineWidth = 2;
  g.beginPath(); g.moveTo(w - 16 - bar * s, 18); g.lineTo(w - 16, 18); g.stroke();
  g.fillStyle = COLORS.text; g.fillText(`${bar * 100} cm`, w - 16 - bar * s, 34);
}

function drawPlot(id, axis, label) {
  const [g, w, h] = fitCanvas($(id));
  g.clearRect(0, 0, w, h);
  const pts = state.points;
  const left = 56, right = w - 8, top = 8, bottom = h - 20;
  g.font = "11px system-ui";
  g.fillStyle = COLORS.text;
  g.fillText(label, left + 6, top + 12);
  if (pts.length < 2) return;
  const [zi, lo, hi] = axis === "x" ? [2, 6, 7] : [3, 8, 9];
  const rel = pts.filter((p) => p[lo] !== null).map((p) => {
    const c = (p[lo] + p[hi]) / 2;
    return { t: p[1], lo: p[lo] - c, hi: p[hi] - c, z: p[zi] === null ? null : p[zi] - c, inside: p[10] };
  });
  if (!rel.length) return;
  const t1 = pts[pts.length - 1][1], t0 = t1 - PLOT_SECONDS;
  let ymax = 0.05;
  for (const r of rel) ymax = Math.max(ymax, r.hi, -r.lo, r.z === null ? 0 : Math.abs(r.z));
  ymax *= 1.15;
  const X = (t) => left + (t - t0) / PLOT_SECONDS * (right - left), Y = (v) => (top + bottom) / 2 - v / ymax * (bottom - top) / 2;
  g.strokeStyle = COLORS.grid; g.lineWidth = 1;
  for (const v of [-ymax / 1.15, 0, ymax / 1.15]) {
    g.beginPath(); g.moveTo(left, Y(v)); g.lineTo(right, Y(v)); g.stroke();
    g.fillStyle = COLORS.text; g.fillText(`${(v * 1000).toFixed(0)} mm`, 4, Y(v) + 4);
  }
  for (let t = Math.ceil(t0); t <= t1; t++) {
    g.beginPath(); g.moveTo(X(t), top); g.lineTo(X(t), bottom); g.stroke();
    g.fillText(`${t} s`, X(t) - 8, h - 5);
  }
  // polygon band
  g.fillStyle = COLORS.band;
  g.beginPath();
  rel.forEach((r, i) => (i ? g.lineTo(X(r.t), Y(r.hi)) : g.moveTo(X(r.t), Y(r.hi))));
  for (let i = rel.length - 1; i >= 0; i--) g.lineTo(X(rel[i].t), Y(rel[i].lo));
  g.closePath(); g.fill();
  g.strokeStyle = COLORS.ok; g.lineWidth = 1;
  for (const k of ["lo", "hi"]) {
    g.beginPath(); rel.forEach((r, i) => (i ? g.lineTo(X(r.t), Y(r[k])) : g.moveTo(X(r.t), Y(r[k])))); g.stroke();
  }
  // ZMP, red where outside the polygon
  g.lineWidth = 2;
  for (let i = 1; i < rel.length; i++) {
    const a = rel[i - 1], b = rel[i];
    if (a.z === null || b.z === null) continue;
    g.strokeStyle = b.inside === false ? COLORS.bad : "#dce3ea";
    g.beginPath(); g.moveTo(X(a.t), Y(a.z)); g.lineTo(X(b.t), Y(b.z)); g.stroke();
  }
}

function frameLoop() {
  if (state.dirty) {
    state.dirty = false;
    drawTop();
    drawPlot("plot-x", "x", "ZMP x − polygon centre (band: polygon extent)");
    drawPlot("plot-y", "y", "ZMP y − polygon centre (band: polygon extent)");
  }
  requestAnimationFrame(frameLoop);
}

connect();
requestAnimationFrame(frameLoop);
