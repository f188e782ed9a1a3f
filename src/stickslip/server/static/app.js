// stickslip control room: plain JavaScript, no build step, nothing fetched from elsewhere.
// The page talks to the server that served it: HTTP for commands, a WebSocket (/api/live) for the live state.
"use strict";

const $ = (id) => document.getElementById(id);
const SPEEDS = ["0.1 µm/s", "0.3 µm/s", "1 µm/s", "3 µm/s", "10 µm/s", "30 µm/s", "100 µm/s"];
const DIRS = { ArrowLeft: "-x", ArrowRight: "+x", ArrowUp: "+y", ArrowDown: "-y", PageUp: "+z", PageDown: "-z",
  a: "-x", d: "+x", w: "+y", s: "-y", r: "+z", f: "-z" };

let token = sessionStorage.getItem("stickslip-token");
if (location.hash.startsWith("#token=")) {  // the part after # never reaches a server or a log
  token = decodeURIComponent(location.hash.slice(7));
  sessionStorage.setItem("stickslip-token", token);
  history.replaceState(null, "", location.pathname);
}

let ws = null;
let state = null;
let lastSeq = 0;
let lastRun = null;
let pathHistory = [];
let jogDir = null;
let jogTimer = null;
let jogSource = null;
let cameraTimer = null;
let shownEvents = 0;
let heldEvents = null;  // while the events of a restarted server are fetched: the live ones that came meanwhile
let lastStateAt = 0;  // Date.now() when the last state message came
let lastStateT = null;  // its server time, epoch s
let staleSince = null;  // Date.now() from when the values shown are no longer live; null while they are
const STALE_AFTER_MS = 3000;  // an open socket silent this long (60 state messages at 20 a second) is not live

// ------------------------------------------------------------------ talking to the server

const UNANSWERED = "the server does not answer";
const NO_JOG = "jog: " + UNANSWERED + "; nothing was sent";  // a jog key held while the socket is closed

async function api(method, path, body) {
  const headers = { "Content-Type": "application/json" };
  if (token) headers.Authorization = "Bearer " + token;
  let r;
  try { r = await fetch(path, { method, headers, body: body === undefined ? undefined : JSON.stringify(body) }); }
  catch (e) { throw new Error(UNANSWERED); }  // no answer at all (the browser says "Failed to fetch")
  let data = null;
  try { data = await r.json(); } catch (e) { data = null; }
  if (r.status === 401) showToken();
  if (!r.ok) throw new Error((data && data.error) || ("HTTP " + r.status));
  return data;
}

function wsSend(msg) {
  if (ws && ws.readyState === WebSocket.OPEN) { ws.send(JSON.stringify(msg)); return true; }
  return false;
}

function connect() {
  const scheme = location.protocol === "https:" ? "wss://" : "ws://";
  ws = new WebSocket(scheme + location.host + "/api/live");
  ws.onopen = async () => {
    if (token) ws.send(JSON.stringify({ type: "auth", token }));
    if (staleSince !== null) setStatus("reconnected; waiting for the state", "offline");  // still greyed
    try { addEvents((await api("GET", "/api/events?after=" + shownEvents)).events); } catch (e) { /* shown as they come */ }
  };
  ws.onmessage = (ev) => {
    const m = JSON.parse(ev.data);
    if (m.seq !== undefined) {
      if (lastRun !== null && m.run !== lastRun) restarted();  // a new server counts its events from 1 again
      lastRun = m.run;
      lastSeq = m.seq;
      lastStateAt = Date.now();
      lastStateT = m.t;
      if (staleSince !== null) live();  // fresh values: live again (a reconnection alone is not enough)
      state = m.state;
      render(state);
      addEvents(m.events || []);
    } else if (m.error) {
      if (jogDir) {  // a jog the server refused (no calibration, a plan running): say so by the pad
        $("jog-note").textContent = m.error;
        releaseJogLocally();
      } else {
        note(m.error, true);
      }
    }
  };
  ws.onclose = (ev) => {
    wentStale("offline since", Date.now());
    releaseJogLocally();
    if (ev.code === 4401) { showToken(); return; }
    setTimeout(connect, 1000);
  };
}

async function restarted() {  // the events shown are the earlier server's: take the new one's from its first
  shownEvents = 0;
  heldEvents = [];
  const li = document.createElement("li");
  li.className = "warning";
  li.textContent = "the server was restarted; its events follow";
  $("events").insertBefore(li, $("events").firstChild);
  for (const where of Object.keys(followed)) {  // a motion of the earlier server: its end was never seen
    note($(where).textContent.replace(/: (running|starting)$/, "") + ": the server was restarted while it ran; " +
      "its end was not seen (the joints say what is kept)", true, where);
  }
  try { showEvents((await api("GET", "/api/events?after=0")).events); } catch (e) { /* the live ones still come */ }
  const held = heldEvents;
  heldEvents = null;
  showEvents(held);
}

// ------------------------------------------------------------------ values no longer live

function clock(ms) { return new Date(ms).toISOString().slice(11, 19); }  // UTC, as the events' times

function wentStale(what, since) {  // grey every live value and say since when, and what they are
  if (staleSince === null) staleSince = since;
  document.body.classList.add("stale");
  setStatus(what + " " + clock(staleSince), "offline");
  const shown = lastStateT === null ? "none received yet" :
    "the last received, at " + clock(lastStateT * 1000) + " UTC, and may no longer be true";
  $("stale-note").textContent = what + " " + clock(staleSince) + " UTC: the greyed values are " + shown +
    "; they are live again when the server sends fresh ones";
  $("stale-note").classList.remove("hidden");
}

function live() {
  staleSince = null;
  if ($("jog-note").textContent === NO_JOG) $("jog-note").textContent = "";
  document.body.classList.remove("stale");
  $("stale-note").classList.add("hidden");
}

setInterval(() => {  // a socket the browser takes for open, with nothing coming: the values are not live either
  if (staleSince === null && lastStateAt && ws && ws.readyState === WebSocket.OPEN &&
      Date.now() - lastStateAt > STALE_AFTER_MS) wentStale("no update since", lastStateAt);
}, 500);

function showToken() {
  $("token-box").classList.remove("hidden");
}

$("token-form").addEventListener("submit", (e) => {
  e.preventDefault();
  token = $("token").value.trim();
  sessionStorage.setItem("stickslip-token", token);
  $("token-box").classList.add("hidden");
  if (ws) ws.close();
  refreshPositions();
});

// ------------------------------------------------------------------ showing the state

function setStatus(text, cls) {
  const s = $("status");
  s.textContent = text;
  s.className = "status " + cls;
}

function um(v, digits = 2) { return (v * 1e6).toFixed(digits); }

function spread(v) {  // a standard deviation in µm, with as many digits as it deserves
  const x = v * 1e6;
  return x >= 100 ? x.toFixed(0) : x >= 1 ? x.toFixed(1) : x.toFixed(3);
}

function render(st) {
  const cal = st.calibration;
  $("device").textContent = st.model + " · " + st.device + " · " +
    (st.rig ? "arm " + st.rig.arm + " of rig " + st.rig.name + " (envelope checked) · " : "") +
    (cal ? "calibration " + cal.day + " (" + cal.method + ")" : "no calibration yet: run the calibration day");
  const m = st.motion;
  const running = m && (m.status === "running" || m.status === "starting");
  setStatus(running ? "moving: " + m.what : "idle", running ? "moving" : "idle");
  renderJoints(st);
  renderTip(st);
  renderMotion(m);
  followMotion(m);
  const planBusy = running && m.kind !== "jog";
  for (const b of document.querySelectorAll("#pad button")) b.disabled = planBusy;
  const jogNote = $("jog-note");
  if (planBusy) jogNote.textContent = "jog is disabled while " + m.what + " runs";
  else if (st.jog && st.jog.message) jogNote.textContent = st.jog.message;
  else if (running || jogNote.textContent.startsWith("jog is disabled")) jogNote.textContent = "";
  if (planBusy && jogDir) releaseJogLocally();
  renderDay(st.day, st.audio);
  if (st.camera) startCamera();
  drawPlot();
}

function renderJoints(st) {
  const box = $("joints");
  if (box.children.length !== st.joints.length) {
    box.innerHTML = "";
    for (const r of st.joints) {
      const d = document.createElement("div");
      d.className = "joint";
      d.innerHTML = '<div class="name">q' + r.joint + '</div><div class="value"></div>' +
        '<div></div><div class="range"><div class="band"></div><div class="mark"></div></div>' +
        '<div></div><div class="source"></div>';
      box.appendChild(d);
    }
  }
  st.joints.forEach((r, i) => {
    const d = box.children[i];
    const sd = r.sd_display ? ' <small>± ' + r.sd_display + '</small>' : "";
    d.querySelector(".value").innerHTML = escapeHtml(r.display) + sd;
    const span = r.upper - r.lower;
    d.querySelector(".mark").style.left = "calc(" + (100 * (r.q - r.lower) / span).toFixed(2) + "% - 2px)";
    const band = d.querySelector(".band");
    if (r.uncertain) {
      band.style.left = (100 * (r.uncertain[0] - r.lower) / span).toFixed(2) + "%";
      band.style.width = Math.max(0.5, 100 * (r.uncertain[1] - r.uncertain[0]) / span).toFixed(2) + "%";
      band.style.display = "block";
    } else {
      band.style.display = "none";
    }
    const src = d.querySelector(".source");
    src.textContent = r.source === "uncertain" ? "uncertain: " + (r.uncertain_display || "") :
      r.source === "moving" ? "moving: between " + (r.uncertain_display || "") : r.source;
    src.className = "source" + (r.source === "uncertain" ? " uncertain" : "");
  });
}

function renderTip(st) {
  const t = st.tip, s = st.tip_sd || [0, 0, 0];
  $("tip").innerHTML = ["x", "y", "z"].map((n, i) =>
    n + " " + um(t[i], 1) + " µm <small>± " + spread(s[i]) + " µm</small>").join("<br>");
  $("truth").textContent = st.truth ?
    "simulator's truth: " + st.truth.display.join(", ") + "; tip " + st.truth.tip.map((v) => um(v, 1)).join(", ") + " µm" : "";
  const p = st.tip;
  const last = pathHistory[pathHistory.length - 1];
  if (!last || Math.hypot(p[0] - last[0], p[1] - last[1], p[2] - last[2]) > 5e-9) {
    pathHistory.push([p[0], p[1], p[2]]);
    if (pathHistory.length > 2000) pathHistory.shift();
  }
}

function renderMotion(m) {
  const box = $("motion");
  if (!m) { box.textContent = "idle"; box.className = "motion live idle"; return; }
  let text = m.what + ": " + m.status + " (" + m.elapsed_s.toFixed(1) + " s)";
  if (m.error) text += " — " + m.error;
  box.textContent = text;
  box.className = "motion live " + m.status;
}

function escapeHtml(s) {
  return String(s).replace(/[&<>"']/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;" })[c]);
}

function addEvents(events) {
  if (heldEvents) heldEvents.push(...events);
  else showEvents(events);
}

function showEvents(events) {
  const list = $("events");
  for (const e of events) {
    if (e.id <= shownEvents) continue;
    shownEvents = e.id;
    const li = document.createElement("li");
    li.className = e.level;
    li.textContent = e.at.slice(11, 19) + " " + e.text;
    list.insertBefore(li, list.firstChild);
    while (list.children.length > 60) list.removeChild(list.lastChild);
    if (/saved|deleted|calibration day .*: done/.test(e.text)) refreshPositions();
  }
}

// ------------------------------------------------------------------ the tip's path

function drawPlot() {
  const c = $("plot");
  const ctx = c.getContext("2d");
  const w = c.width, h = c.height;
  ctx.clearRect(0, 0, w, h);
  if (!state) return;
  const view = $("view").value;
  const ax = 0, ay = view === "xz" ? 2 : 1;
  const plan = state.motion && state.motion.path ? state.motion.path : [];
  const pts = pathHistory.concat(plan, [state.tip]);
  let xmin = Infinity, xmax = -Infinity, ymin = Infinity, ymax = -Infinity;
  for (const p of pts) {
    xmin = Math.min(xmin, p[ax]); xmax = Math.max(xmax, p[ax]);
    ymin = Math.min(ymin, p[ay]); ymax = Math.max(ymax, p[ay]);
  }
  let span = Math.max(xmax - xmin, ymax - ymin, 20e-6) * 1.2;
  const cx = (xmin + xmax) / 2, cy = (ymin + ymax) / 2;
  const scale = Math.min(w, h - 30) / span;
  const X = (p) => w / 2 + (p[ax] - cx) * scale;
  const Y = (p) => (h - 30) / 2 - (p[ay] - cy) * scale;
  ctx.lineWidth = 2;
  ctx.strokeStyle = "#1f5fbf";
  ctx.beginPath();
  pathHistory.forEach((p, i) => (i ? ctx.lineTo(X(p), Y(p)) : ctx.moveTo(X(p), Y(p))));
  ctx.stroke();
  if (plan.length) {
    ctx.setLineDash([6, 4]);
    ctx.strokeStyle = "#a86400";
    ctx.beginPath();
    plan.forEach((p, i) => (i ? ctx.lineTo(X(p), Y(p)) : ctx.moveTo(X(p), Y(p))));
    ctx.stroke();
    ctx.setLineDash([]);
  }
  const t = state.tip, sd = state.tip_sd || [0, 0, 0];
  const r = Math.max(3, Math.hypot(sd[ax], sd[ay]) * scale);
  ctx.strokeStyle = "#b3261e";
  ctx.fillStyle = "rgba(179, 38, 30, 0.15)";
  if (r < Math.min(w, h) / 2) {  // a spread larger than the plot is said in the joints' panel, not painted over it
    ctx.beginPath(); ctx.arc(X(t), Y(t), r, 0, 2 * Math.PI); ctx.fill(); ctx.stroke();
  }
  ctx.fillStyle = "#b3261e";
  ctx.beginPath(); ctx.arc(X(t), Y(t), 3, 0, 2 * Math.PI); ctx.fill();
  // a scale bar and the axes' names
  const nice = [1, 2, 5, 10, 20, 50, 100, 200, 500, 1000, 2000, 5000, 10000];
  const barUm = nice.find((v) => v * 1e-6 * scale > w / 6) || 10000;
  ctx.fillStyle = "#1d2430";
  ctx.fillRect(10, h - 14, barUm * 1e-6 * scale, 3);
  ctx.font = "12px system-ui, sans-serif";
  ctx.fillText(barUm >= 1000 ? barUm / 1000 + " mm" : barUm + " µm", 10, h - 18);
  ctx.fillText(view === "xz" ? "x → , z ↑ (side view)" : "x → , y ↑ (top view)", w - 150, h - 6);
}

$("view").addEventListener("change", drawPlot);
$("clear-path").addEventListener("click", () => { pathHistory = []; drawPlot(); });

// ------------------------------------------------------------------ STOP

// One press goes both ways. The socket is the quicker (open already: no connection to make), but a socket the
// browser still takes for open may be dead (a server restarted, a link dropped) and sends nothing; the POST makes
// its own connection, gets through while the socket reconnects, and its failure is said. The press's id lets the
// server say the STOP once.
let presses = 0;

async function stopAll() {
  releaseJogLocally();
  const press = Date.now().toString(36) + "-" + (++presses) + "-" + Math.random().toString(36).slice(2, 8);
  const onSocket = wsSend({ type: "stop", press });
  try { await api("POST", "/api/stop?press=" + encodeURIComponent(press)); } catch (e) {
    const lost = onSocket ? ": it went on the live socket too, which may be as dead" : ": this STOP did not reach it";
    note("STOP: " + e.message + (e.message === UNANSWERED ? lost : ""), true);
  }
}

$("stop").addEventListener("click", stopAll);

// ------------------------------------------------------------------ jog: pad, keyboard, gamepad

function jogStart(dir, source) {
  if (jogDir === dir) return;
  jogDir = dir;
  jogSource = source;
  for (const b of document.querySelectorAll("#pad button")) b.classList.toggle("held", b.dataset.dir === dir);
  sendJog();
  clearInterval(jogTimer);
  jogTimer = setInterval(sendJog, 50);  // keep-alives: the server lets go 0.15 s after the last
}

function sendJog() {
  if (!jogDir) return;
  if (!wsSend({ type: "jog", direction: jogDir, speed: Number($("speed").value) })) {
    releaseJogLocally();
    $("jog-note").textContent = NO_JOG;
  }
}

function jogStop() {
  if (!jogDir) return;
  releaseJogLocally();
  wsSend({ type: "release" });
}

function releaseJogLocally() {
  jogDir = null;
  jogSource = null;
  clearInterval(jogTimer);
  jogTimer = null;
  for (const b of document.querySelectorAll("#pad button")) b.classList.remove("held");
}

for (const b of document.querySelectorAll("#pad button")) {
  b.addEventListener("pointerdown", (e) => {
    if (b.disabled) return;
    e.preventDefault();
    b.setPointerCapture(e.pointerId);
    jogStart(b.dataset.dir, "pointer");
  });
  for (const ev of ["pointerup", "pointercancel", "lostpointercapture"]) {
    b.addEventListener(ev, () => { if (jogSource === "pointer") jogStop(); });
  }
  b.addEventListener("contextmenu", (e) => e.preventDefault());
}

function typing(e) {
  const t = e.target;
  return t && (t.tagName === "INPUT" || t.tagName === "SELECT" || t.tagName === "TEXTAREA");
}

document.addEventListener("keydown", (e) => {
  if (e.key === "Escape" || (e.key === " " && !typing(e))) {
    e.preventDefault();
    stopAll();
    return;
  }
  if (typing(e)) return;
  const key = e.key.length === 1 ? e.key.toLowerCase() : e.key;
  const dir = DIRS[key];
  if (dir) {
    e.preventDefault();
    const pad = document.querySelector('#pad button[data-dir="' + dir + '"]');
    if (pad && !pad.disabled) jogStart(dir, "key:" + key);
  } else if (/^[1-7]$/.test(key)) {
    $("speed").value = key;
    speedLabel();
  }
});

document.addEventListener("keyup", (e) => {
  const key = e.key.length === 1 ? e.key.toLowerCase() : e.key;
  if (jogSource === "key:" + key) jogStop();
});

window.addEventListener("blur", jogStop);
document.addEventListener("visibilitychange", () => { if (document.hidden) jogStop(); });

function speedLabel() { $("speed-out").textContent = SPEEDS[Number($("speed").value) - 1]; }
$("speed").addEventListener("input", speedLabel);

let padPrev = {};
function pollGamepad() {
  const pads = navigator.getGamepads ? navigator.getGamepads() : [];
  const gp = Array.from(pads || []).find((p) => p && p.connected);
  if (!gp) { $("gamepad").textContent = "no gamepad (connect one and press a button)"; return; }
  const held = (i) => gp.buttons[i] && gp.buttons[i].pressed;
  const deadman = held(5) || held(7);
  $("gamepad").textContent = gp.id.slice(0, 40) + ": hold the right shoulder button and steer; B = STOP" +
    (deadman ? " (held)" : "");
  if (held(1) && !padPrev[1]) stopAll();
  if (held(12) && !padPrev[12]) { $("speed").value = Math.min(7, Number($("speed").value) + 1); speedLabel(); }
  if (held(13) && !padPrev[13]) { $("speed").value = Math.max(1, Number($("speed").value) - 1); speedLabel(); }
  padPrev = { 1: held(1), 12: held(12), 13: held(13) };
  const axes = [gp.axes[0] || 0, -(gp.axes[1] || 0), -(gp.axes[3] || 0)];
  let best = -1, size = 0.5;
  axes.forEach((v, i) => { if (Math.abs(v) > size) { size = Math.abs(v); best = i; } });
  const dir = deadman && best >= 0 ? (axes[best] > 0 ? "+" : "-") + "xyz"[best] : null;
  if (dir) jogStart(dir, "gamepad");
  else if (jogSource === "gamepad") jogStop();
}
setInterval(pollGamepad, 50);

// ------------------------------------------------------------------ moves

function note(text, error, where = "move-msg") {
  const el = $(where);
  el.textContent = text;
  el.className = "msg " + (error ? "err" : "ok");
  delete followed[where];  // the box says something else now: no motion's news overwrites it
}

// the motion each message box last started (its id): the box follows it from the live state to its end
const followed = {};
const FAILED = ["failed", "refused"];

function started(m, where = "move-msg") {  // a motion the server took: say so, and follow it
  motionNote(m, where);
  followed[where] = m.id;
}

function motionNote(m, where) {  // a motion under way is a live value (greyed when not live); its end is not
  note(m.what + ": " + m.status + (m.error ? " — " + m.error : ""), FAILED.includes(m.status), where);
  $(where).classList.toggle("live", m.status === "running" || m.status === "starting");
}

function followMotion(m) {  // a followed motion's box says where it got: running, then done / stopped / failed
  if (!m) return;
  for (const where of Object.keys(followed)) {
    if (followed[where] !== m.id) continue;
    motionNote(m, where);
    if (m.status === "running" || m.status === "starting") followed[where] = m.id;  // its end is said once
  }
}

$("move-form").addEventListener("submit", async (e) => {
  e.preventDefault();
  const body = { joint: Number($("move-joint").value) };
  body[$("move-mode").value] = $("move-amount").value.trim();
  try {
    const m = await api("POST", "/api/move", body);
    started(m);
  } catch (err) { note(err.message, true); }
});

$("reach-form").addEventListener("submit", async (e) => {
  e.preventDefault();
  const by = ["reach-x", "reach-y", "reach-z"].map((id) => {  // a bare number is in the boxes' µm; "1mm" as typed
    const v = $(id).value.trim();
    return /^[-+]?(\d+\.?\d*|\.\d+)(e[-+]?\d+)?$/i.test(v) ? v + "um" : v;
  });
  try {
    const m = await api("POST", "/api/reach", { by });
    started(m);
  } catch (err) { note(err.message, true); }
});

// ------------------------------------------------------------------ named positions

async function refreshPositions() {
  let data;
  try { data = await api("GET", "/api/positions"); } catch (e) { return; }
  const list = $("positions");
  list.innerHTML = "";
  for (const p of data.positions) {
    const li = document.createElement("li");
    li.innerHTML = '<span class="pname"></span><span class="pq"></span>' +
      '<button class="go">Go</button><button class="del" aria-label="delete">✕</button>';
    li.querySelector(".pname").textContent = p.name + (p.source === "rig" ? " (rig file)" : "");
    li.querySelector(".pq").textContent = p.display.join(", ");
    if (p.source === "rig") li.querySelector(".del").remove();  // changed in the rig file, not here
    li.querySelector(".go").addEventListener("click", async () => {
      try { const m = await api("POST", "/api/positions/" + encodeURIComponent(p.name) + "/go"); started(m, "pos-msg"); }
      catch (err) { note(err.message, true, "pos-msg"); }
    });
    if (p.source !== "rig") li.querySelector(".del").addEventListener("click", async () => {
      try { await api("DELETE", "/api/positions/" + encodeURIComponent(p.name)); refreshPositions(); }
      catch (err) { note(err.message, true, "pos-msg"); }
    });
    list.appendChild(li);
  }
  if (!data.positions.length) list.innerHTML = '<li class="small-text">none yet: move somewhere, name it, Save here</li>';
}

$("save-form").addEventListener("submit", async (e) => {
  e.preventDefault();
  const name = $("pos-name").value.trim();
  try {
    await api("POST", "/api/positions", { name });
    note("saved " + name, false, "pos-msg");
    $("pos-name").value = "";
    refreshPositions();
  } catch (err) { note(err.message, true, "pos-msg"); }
});

// ------------------------------------------------------------------ the calibration day

function renderDay(day, audio) {
  const plan = $("day-plan");
  const running = state && state.motion && state.motion.kind === "day" &&
    (state.motion.status === "running" || state.motion.status === "starting");
  $("day-start").disabled = running;
  if (!day) {
    if (!plan.children.length) plan.innerHTML = "";
    $("day-now").textContent = "";
    return;
  }
  if (plan.children.length !== day.plan.length) {
    plan.innerHTML = "";
    for (const t of day.plan) {
      const li = document.createElement("li");
      li.textContent = t.describe;
      plan.appendChild(li);
    }
  }
  const p = day.progress;
  const now = p ? p.index : day.done;
  Array.from(plan.children).forEach((li, i) => {
    li.className = i < day.done ? "done" : (running && i === now ? "now" : "");
  });
  let text = "";
  if (running && p) {
    text = "traverse " + (p.index + 1) + " of " + p.total + ": " + p.stage;
    if (p.stage === "traversing") text += ", " + p.steps + " steps, " + p.device_s.toFixed(1) + " s";
    if (p.stage === "calibrating") text = "calibrating from the 14 traverses…";
  } else if (day.result) {
    text = "done: calibration " + day.result.day + " stored (id " + day.result.calibration_id + "), now in use";
  } else if (day.done < day.total) {
    text = day.done + " of " + day.total + " traverses measured; the day stopped: Resume goes on from the next";
  }
  $("day-now").textContent = text;
  $("day-resume").classList.toggle("hidden", running || !!day.result || day.done === 0);
  $("day-pose").classList.toggle("hidden", !day.waiting_for_pose);
  const db = audio && audio.level_db !== null ? audio.level_db : null;
  $("meter-bar").style.width = db === null ? "0" : Math.max(0, Math.min(100, (db + 90) / 90 * 100)).toFixed(1) + "%";
  $("meter-out").textContent = db === null ? "—" : db.toFixed(1) + " dBFS" +
    (audio.band_hz ? " in " + Math.round(audio.band_hz[0]) + "–" + Math.round(audio.band_hz[1]) + " Hz" : "");
  const res = $("day-result");
  if (day.result && !res.dataset.shown) {
    res.dataset.shown = "1";
    const withErrors = day.result.parameters.some((q) => q.stderr !== null);
    const rows = day.result.parameters.map((q) => "<tr><td>" + escapeHtml(q.label) + "</td><td>" +
      fmtParam(q.value, q.unit) + "</td>" +
      (withErrors ? "<td>" + (q.stderr === null ? "" : "± " + fmtParam(q.stderr, q.unit)) + "</td>" : "") + "</tr>");
    res.innerHTML = "<h3>Result</h3><table class='params'><tr><th>parameter</th><th>value</th>" +
      (withErrors ? "<th>standard error</th>" : "") + "</tr>" + rows.join("") + "</table>" +
      "<p class='small-text'>" + escapeHtml(day.result.method) + "; stored as calibration #" +
      day.result.calibration_id + " and in use for every move from now on.</p>";
  }
  if (!day.result) delete res.dataset.shown;
}

function fmtParam(v, unit) {
  if (unit === "m") return (v * 1e9).toFixed(1) + " nm";
  if (unit === "rad") return (v * 1e6).toFixed(2) + " µrad";
  return Number(v).toFixed(4);
}

$("day-start").addEventListener("click", async () => {
  $("day-result").innerHTML = "";
  try { await api("POST", "/api/day", {}); } catch (e) { $("day-now").textContent = e.message; }
});
$("day-resume").addEventListener("click", async () => {
  try { await api("POST", "/api/day", { resume: true }); } catch (e) { $("day-now").textContent = e.message; }
});
$("day-pose").addEventListener("click", async () => {
  try { await api("POST", "/api/day/pose-set"); } catch (e) { $("day-now").textContent = e.message; }
});

// ------------------------------------------------------------------ calibration, history, ANOVA

$("show-cal").addEventListener("click", async () => {
  try {
    const d = await api("GET", "/api/calibration");
    $("history-out").textContent = d.calibration ? d.report : "no calibration yet: run the calibration day";
  } catch (e) { $("history-out").textContent = e.message; }
});
$("show-history").addEventListener("click", async () => {
  try {
    const d = await api("GET", "/api/history");
    const lines = ["day          traverses  calibrations"];
    for (const s of d.sessions) {
      lines.push(String(s.day).padEnd(12) + " " + String(s.traverses).padStart(9) + "  " +
        (s.calibrations || []).map((c) => "#" + c.id + " " + c.method).join(", "));
    }
    if (!d.sessions.length) lines.push("nothing recorded yet");
    $("history-out").textContent = lines.join("\n");
  } catch (e) { $("history-out").textContent = e.message; }
});
$("show-anova").addEventListener("click", async () => {
  $("history-out").textContent = "computing…";
  try { $("history-out").textContent = (await api("GET", "/api/anova")).report; }
  catch (e) { $("history-out").textContent = e.message; }
});

// ------------------------------------------------------------------ the camera (when the server has one)

function startCamera() {
  if (cameraTimer) return;
  $("camera-panel").classList.remove("hidden");
  const img = $("frame");
  let busy = false;
  cameraTimer = setInterval(async () => {
    if (busy) return;
    busy = true;
    try {
      const headers = token ? { Authorization: "Bearer " + token } : {};
      const r = await fetch("/api/camera/frame", { headers });
      if (r.ok) {
        const blob = await r.blob();
        const url = URL.createObjectURL(blob);
        img.onload = () => URL.revokeObjectURL(url);
        img.src = url;
        img.classList.remove("stale");
        const info = await api("GET", "/api/camera");
        drawOverlay(info, Number(r.headers.get("X-Frame-Width")), Number(r.headers.get("X-Frame-Height")));
      } else {
        let data = null;
        try { data = await r.json(); } catch (e) { data = null; }
        cameraLost((data && data.error) || ("HTTP " + r.status));
      }
    } catch (e) { cameraLost(UNANSWERED); }  // the next frame tries again
    busy = false;
  }, 500);
}

function cameraLost(why) {  // no new frame: the last one stays, greyed, and says it is old; no tip is marked on it
  $("frame").classList.add("stale");
  const c = $("overlay");
  c.getContext("2d").clearRect(0, 0, c.width, c.height);
  $("camera-tip").textContent = "no new frame: " + why + " (the frame shown is the last one received)";
}

function drawOverlay(info, fw, fh) {
  const c = $("overlay");
  c.width = fw; c.height = fh;
  const ctx = c.getContext("2d");
  ctx.clearRect(0, 0, fw, fh);
  if (info.path_px && info.path_px.length) {
    ctx.setLineDash([6, 4]);
    ctx.strokeStyle = "#ffb000";
    ctx.lineWidth = Math.max(1, fw / 300);
    ctx.beginPath();
    info.path_px.forEach((p, i) => (i ? ctx.lineTo(p[0], p[1]) : ctx.moveTo(p[0], p[1])));
    ctx.stroke();
    ctx.setLineDash([]);
  }
  const t = info.tip;
  $("camera-tip").textContent = t ? "tip at (" + t.x.toFixed(1) + ", " + t.y.toFixed(1) + ") px" +
    (t.sd !== null ? " ± " + t.sd.toFixed(1) : "") : "tip not tracked";
  if (t) {
    const r = Math.max(4, fw / 60);
    ctx.strokeStyle = "#ff2d55";
    ctx.lineWidth = Math.max(1.5, fw / 250);
    ctx.beginPath();
    ctx.moveTo(t.x - 2 * r, t.y); ctx.lineTo(t.x - r / 2, t.y); ctx.moveTo(t.x + r / 2, t.y); ctx.lineTo(t.x + 2 * r, t.y);
    ctx.moveTo(t.x, t.y - 2 * r); ctx.lineTo(t.x, t.y - r / 2); ctx.moveTo(t.x, t.y + r / 2); ctx.lineTo(t.x, t.y + 2 * r);
    ctx.stroke();
    ctx.beginPath(); ctx.arc(t.x, t.y, r, 0, 2 * Math.PI); ctx.stroke();
  }
}

// ------------------------------------------------------------------ start

speedLabel();
refreshPositions();
connect();
