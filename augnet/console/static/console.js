// augnet console page: no framework, no external assets.
// Live state arrives over the websocket /api/live (a snapshot, then events); when the socket cannot be
// kept open the page polls /api/live/snapshot instead and retries the socket. Alarms, stations and the
// audit log are read over the REST API. Every value from the server is set with textContent, never HTML.
"use strict";

const POLL_INTERVAL_MS = 1000;        // snapshot polling while the websocket is down
const WS_RETRY_MS = 5000;             // then try the websocket again
const ALARM_REFRESH_MS = 2000;        // alarms are raised in the store by the system: poll them
const STATIONS_REFRESH_MS = 5000;     // registry and along-track positions of stations
const AUDIT_ROWS = 15;
const SVG_NS = "http://www.w3.org/2000/svg";
const DIAGRAM = { left: 40, right: 960, trackY: 150, stationY: 168, trainY: 132, baselineTopY: 20, labelGapPx: 36 };
const ROLE_RANK = { viewer: 0, operator: 1, admin: 2 };

const state = {
  token: sessionStorage.getItem("augnet.token"),
  me: null,
  stations: new Map(),   // code -> merged registry + live fields
  baselines: [],
  trains: new Map(),     // id -> TrainLive
  network: {},
  line: {},
  alarms: [],
  feed: "offline",
  ws: null,
  pollTimer: null,
  renderQueued: false,
  dirty: new Set(),      // what changed since the last frame: "trains" alone is the frequent case
};

const $ = (id) => document.getElementById(id);

function fmt(v, digits) {
  if (v === null || v === undefined || Number.isNaN(v)) return "–";
  return typeof v === "number" ? v.toFixed(digits) : String(v);
}

function el(tag, attrs, text) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) e.setAttribute(k, v);
  if (text !== undefined) e.textContent = text;
  return e;
}

function svg(tag, attrs, text) {
  const e = document.createElementNS(SVG_NS, tag);
  for (const [k, v] of Object.entries(attrs || {})) e.setAttribute(k, v);
  if (text !== undefined) e.textContent = text;
  return e;
}

function td(text, cls) { return el("td", cls ? { class: cls } : {}, text); }

// ---- API ---------------------------------------------------------------------------------------------

async function api(method, path, body) {
  const headers = { "Accept": "application/json" };
  if (state.token) headers["Authorization"] = "Bearer " + state.token;
  if (body !== undefined) headers["Content-Type"] = "application/json";
  const resp = await fetch(path, { method, headers, body: body === undefined ? undefined : JSON.stringify(body) });
  if (resp.status === 401) { logout(false); throw new Error("not logged in"); }
  if (!resp.ok) {
    let detail = resp.statusText;
    try { detail = JSON.stringify((await resp.json()).detail); } catch (e) { /* not JSON */ }
    throw new Error(method + " " + path + ": " + resp.status + " " + detail);
  }
  return resp.status === 204 ? null : resp.json();
}

// ---- login -------------------------------------------------------------------------------------------

async function login(ev) {
  ev.preventDefault();
  $("login-error").textContent = "";
  try {
    const resp = await fetch("/api/auth/login", {
      method: "POST", headers: { "Content-Type": "application/json" },
      body: JSON.stringify({ name: $("login-name").value, password: $("login-password").value }),
    });
    if (!resp.ok) { $("login-error").textContent = resp.status === 401 ? "wrong name or password" : "login failed"; return; }
    const tok = await resp.json();
    state.token = tok.token;
    sessionStorage.setItem("augnet.token", tok.token);
    $("login-password").value = "";
    await start();
  } catch (e) { $("login-error").textContent = String(e); }
}

function logout(tellServer) {
  if (tellServer && state.token) api("POST", "/api/auth/logout").catch(() => {});
  state.token = null; state.me = null;
  sessionStorage.removeItem("augnet.token");
  if (state.ws) { state.ws.onclose = null; state.ws.close(); state.ws = null; }
  clearTimeout(state.pollTimer);
  $("main").hidden = true; $("login").hidden = false; $("logout").hidden = true; $("whoami").textContent = "";
  setFeed("offline");
}

// ---- live feed ---------------------------------------------------------------------------------------

function setFeed(mode) {
  state.feed = mode;
  const f = $("feed-status");
  f.textContent = mode; f.className = "feed " + mode;
}

function applySnapshot(s) {
  state.trains = new Map((s.trains || []).map((t) => [t.id, t]));
  for (const st of s.stations || []) mergeLiveStation(st);
  state.baselines = s.baselines || [];
  state.network = s.network || {};
  state.line = s.line || {};
}

function mergeLiveStation(st) {
  const cur = state.stations.get(st.id) || { code: st.id, in_store: false };
  cur.live = { up: st.up, last_data_age_s: st.last_data_age_s, satellites: st.satellites };
  cur.rtcm_station_id = st.station_id;
  cur.enabled = st.enabled;
  if (st.along_km !== null && st.along_km !== undefined) cur.along_km = st.along_km;
  state.stations.set(st.id, cur);
}

function applyEvent(ev) {
  state.dirty.add(ev.type === "train" || ev.type === "train.removed" ? "trains" : "all");
  switch (ev.type) {
    case "snapshot": applySnapshot(ev); break;
    case "train": state.trains.set(ev.train.id, ev.train); break;
    case "train.removed": state.trains.delete(ev.id); break;
    case "station": mergeLiveStation(ev.station); break;
    case "station.removed": state.stations.delete(ev.id); break;
    case "baselines": state.baselines = ev.baselines; break;
    case "network": state.network = ev.network; break;
    case "line": state.line = ev.line; break;
    case "alarm": refreshAlarms(); refreshAudit(); break;
    case "station.changed": refreshStations(); refreshAudit(); break;
  }
}

function connectFeed() {
  if (!state.token) return;
  const proto = location.protocol === "https:" ? "wss:" : "ws:";
  let ws;
  try { ws = new WebSocket(proto + "//" + location.host + "/api/live?token=" + encodeURIComponent(state.token)); }
  catch (e) { startPolling(); return; }
  state.ws = ws;
  ws.onopen = () => { clearTimeout(state.pollTimer); setFeed("live"); };
  ws.onmessage = (msg) => {
    const data = JSON.parse(msg.data);
    for (const ev of data.events || []) applyEvent(ev);
    queueRender();
  };
  ws.onclose = (ev) => {
    state.ws = null;
    if (ev.code === 4401) { logout(false); return; }
    startPolling();
  };
}

function startPolling() {
  if (!state.token) return;
  setFeed("polling");
  const started = Date.now();
  const tick = async () => {
    try { applySnapshot(await api("GET", "/api/live/snapshot")); queueRender("all"); } catch (e) { /* next tick */ }
    if (!state.token) return;
    if (Date.now() - started >= WS_RETRY_MS) { connectFeed(); return; }
    state.pollTimer = setTimeout(tick, POLL_INTERVAL_MS);
  };
  tick();
}

// ---- REST-backed sections ----------------------------------------------------------------------------

async function refreshAlarms() {
  try { state.alarms = await api("GET", "/api/alarms"); renderAlarms(); } catch (e) { console.warn(e); }
}

async function refreshStations() {
  try {
    const list = await api("GET", "/api/stations");
    for (const s of list) {
      const cur = state.stations.get(s.code) || {};
      state.stations.set(s.code, Object.assign(cur, s, { live: s.live || cur.live }));
    }
    queueRender("all");
  } catch (e) { console.warn(e); }
}

async function refreshAudit() {
  try {
    const rows = await api("GET", "/api/audit?limit=" + AUDIT_ROWS);
    const body = $("audit").tBodies[0];
    body.replaceChildren(...rows.map((a) => {
      const tr = el("tr", { "data-audit": String(a.id) });
      tr.append(td(String(a.id)), td(a.at.replace("T", " ").slice(0, 19)), td(a.actor), td(a.action), td(a.target));
      return tr;
    }));
  } catch (e) { console.warn(e); }
}

async function acknowledge(id, button) {
  button.disabled = true;
  try { await api("POST", "/api/alarms/" + id + "/acknowledge"); }
  catch (e) { button.disabled = false; alert(String(e)); return; }
  await Promise.all([refreshAlarms(), refreshAudit()]);
}

async function setStationEnabled(code, enabled) {
  try { await api("POST", "/api/stations/" + encodeURIComponent(code) + (enabled ? "/enable" : "/disable")); }
  catch (e) { alert(String(e)); return; }
  await Promise.all([refreshStations(), refreshAudit()]);
}

// ---- rendering ---------------------------------------------------------------------------------------

function queueRender(part) {
  if (part) state.dirty.add(part);
  if (state.renderQueued) return;
  state.renderQueued = true;
  requestAnimationFrame(() => { state.renderQueued = false; render(); });
}

function render() {
  const all = state.dirty.has("all");
  state.dirty.clear();
  if (all) { renderSummary(); renderStatic(); renderStations(); }
  renderTrainMarkers(); renderTrains();
}

// The centre's summary is free-form; these keys (first found of each group) make the header, the rest is in
// its tooltip.
const SUMMARY_FIELDS = [
  [["epoch_utc", "epoch", "epoch_gpst"], "epoch"],
  [["master", "master_station"], "master"],
  [["quality", "quality_flag"], "quality"],
  [["model", "interpolation", "interpolation_model"], "model"],
  [["satellites"], "satellites"],
  [["excluded", "excluded_satellites"], "excluded"],
  [["correction_age_p99_s"], "corr. age p99 s"],
];

function summaryValue(v) {
  if (Array.isArray(v)) return v.length ? v.join(" ") : "none";
  if (typeof v === "number") return Number.isInteger(v) ? String(v) : v.toFixed(2);
  if (v !== null && typeof v === "object") return Object.entries(v).map(([k, x]) => k + " " + summaryValue(x)).join(", ");
  return String(v);
}

function renderSummary() {
  const n = state.network || {};
  const box = $("network-summary");
  const spans = [];
  for (const [keys, label] of SUMMARY_FIELDS) {
    const k = keys.find((key) => n[key] !== undefined && n[key] !== null);
    if (k === undefined) continue;
    const s = el("span", { "data-summary": k });
    s.append(el("b", {}, label + ": "), summaryValue(n[k]));
    spans.push(s);
  }
  box.replaceChildren(...spans);
  box.title = Object.entries(n).map(([k, v]) => k + ": " + summaryValue(v)).join("\n");
}

function lineLength() {
  if (state.line && state.line.length_km) return state.line.length_km;
  let m = 0;
  for (const s of state.stations.values()) if (s.along_km != null) m = Math.max(m, s.along_km);
  for (const t of state.trains.values()) if (t.along_km != null) m = Math.max(m, t.along_km);
  return m > 0 ? m * 1.05 : 100;
}

function xOf(km, length) {
  return DIAGRAM.left + (DIAGRAM.right - DIAGRAM.left) * Math.min(Math.max(km / length, 0), 1);
}

function renderStatic() {
  const length = lineLength();
  state.drawnLength = length;
  $("line-name").textContent = state.line && state.line.id ? state.line.id + " · " + fmt(length, 1) + " km" : "";
  // track and km ticks
  const track = $("layer-track");
  const step = [1, 2, 5, 10, 20, 50, 100, 200].find((s) => length / s <= 12) || 500;
  const tr = [svg("line", { class: "track", x1: DIAGRAM.left, x2: DIAGRAM.right, y1: DIAGRAM.trackY, y2: DIAGRAM.trackY })];
  for (let km = 0; km <= length + 1e-9; km += step) {
    const x = xOf(km, length);
    tr.push(svg("line", { class: "tick", x1: x, x2: x, y1: DIAGRAM.trackY + 4, y2: DIAGRAM.trackY + 10 }));
    tr.push(svg("text", { x: x, y: 222, "text-anchor": "middle" }, km + " km"));
  }
  track.replaceChildren(...tr);

  // stations
  const stationX = new Map();
  const st = [];
  const placed = [...state.stations.values()].filter((s) => s.along_km != null).sort((a, b) => a.along_km - b.along_km);
  let lastLabelX = -Infinity, row = 0;
  for (const s of placed) {
    const x = xOf(s.along_km, length);
    stationX.set(s.code, x);
    row = x - lastLabelX < DIAGRAM.labelGapPx ? 1 - row : 0;  // close neighbours: labels on alternate rows
    lastLabelX = x;
    const live = s.live || {};
    const cls = s.enabled === false ? "disabled" : live.up ? "up" : "down";
    const g = svg("g", { class: "station " + cls, "data-station": s.code, transform: `translate(${x.toFixed(1)},${DIAGRAM.stationY})` });
    g.append(svg("polygon", { points: "0,-10 8,6 -8,6" }),
      svg("text", { y: 22 + row * 13, "text-anchor": "middle" }, s.code));
    g.append(svg("title", {}, `${s.code}: ${cls}, ${live.satellites ?? "?"} satellites`));
    st.push(g);
  }
  $("layer-stations").replaceChildren(...st);

  // baselines: arcs above the track between their stations, coloured by ambiguity state
  const bl = [];
  for (const b of state.baselines) {
    const xa = stationX.get(b.a), xb = stationX.get(b.b);
    if (xa === undefined || xb === undefined) continue;
    const mid = (xa + xb) / 2;
    const lift = Math.min(DIAGRAM.trackY - DIAGRAM.baselineTopY, 25 + Math.abs(xb - xa) / 3);
    const p = svg("path", { class: "baseline " + b.state, "data-baseline": b.a + "-" + b.b,
      d: `M ${xa} ${DIAGRAM.trackY - 4} Q ${mid} ${DIAGRAM.trackY - 4 - 2 * lift} ${xb} ${DIAGRAM.trackY - 4}` });
    p.append(svg("title", {}, `${b.a}–${b.b} ${fmt(b.length_km, 1)} km: ${b.state}, fixed ${fmt(100 * b.fixed_fraction, 0)} %, residual ${fmt(b.residual_rms_cm, 1)} cm`));
    bl.push(p);
  }
  $("layer-baselines").replaceChildren(...bl);
}

function renderTrainMarkers() {
  // markers are moved in place (kept across renders so the page does not flicker)
  if (state.drawnLength === undefined || lineLength() !== state.drawnLength) renderStatic();
  const length = state.drawnLength;
  const layer = $("layer-trains");
  const seen = new Set();
  for (const t of state.trains.values()) {
    if (t.along_km == null) continue;
    seen.add(t.id);
    let g = layer.querySelector(`g[data-train="${CSS.escape(t.id)}"]`);
    if (!g) {
      g = svg("g", { "data-train": t.id });
      g.append(svg("rect", { x: -22, y: -9, width: 44, height: 18, rx: 4 }), svg("text", { y: 4, "text-anchor": "middle" }, t.id));
      g.append(svg("title"));
      layer.append(g);
    }
    const x = xOf(t.along_km, length);
    g.setAttribute("class", "train " + t.fix_state);
    g.setAttribute("transform", `translate(${x.toFixed(1)},${DIAGRAM.trainY})`);
    g.setAttribute("data-along-km", t.along_km.toFixed(3));
    g.querySelector("title").textContent = `${t.id}: km ${fmt(t.along_km, 3)}, ${t.fix_state}, HPL ${fmt(t.hpl_m, 2)} m`;
  }
  for (const g of [...layer.children]) if (!seen.has(g.getAttribute("data-train"))) g.remove();
}

function renderTrains() {
  const now = Date.now() / 1000;
  const trains = [...state.trains.values()].sort((a, b) => a.id.localeCompare(b.id));
  $("train-count").textContent = "(" + trains.length + ")";
  $("trains").tBodies[0].replaceChildren(...trains.map((t) => {
    const tr = el("tr", { "data-train": t.id });
    const fix = el("td"); fix.append(el("span", { class: "fixstate " + t.fix_state }, t.fix_state));
    tr.append(td(t.id), td(t.track_id ?? "–"), td(fmt(t.along_km, 3), "num"), td(fmt(t.cross_track_m, 2), "num"), fix,
      td(fmt(t.correction_age_s, 1), "num"), td(fmt(t.hpl_m, 2), "num"), td(fmt(t.vpl_m, 2), "num"),
      td(fmt(t.speed_kmh, 0), "num"), td(fmt(t.lat_deg, 6), "num"), td(fmt(t.lon_deg, 6), "num"),
      td(fmt(Math.max(0, now - t.updated_unix), 1), "num"));
    return tr;
  }));
}

function canOperate() { return state.me && ROLE_RANK[state.me.role] >= ROLE_RANK.operator; }

function renderAlarms() {
  const open = state.alarms;
  $("alarm-count").textContent = "(" + open.filter((a) => a.state === "raised").length + " unacknowledged)";
  $("alarms-empty").hidden = open.length > 0;
  $("alarms").tBodies[0].replaceChildren(...open.map((a) => {
    const tr = el("tr", { "data-alarm": String(a.id), "data-state": a.state, class: "sev-" + a.severity + " state-" + a.state });
    const action = el("td");
    if (a.state === "raised" && canOperate()) {
      const b = el("button", { type: "button", class: "ack", "data-alarm": String(a.id) }, "Acknowledge");
      b.addEventListener("click", () => acknowledge(a.id, b));
      action.append(b);
    } else if (a.state === "acknowledged") {
      action.textContent = "by " + a.acknowledged_by;
    }
    tr.append(td(String(a.id)), td(a.severity), td(a.kind), td(a.subject), td(a.message),
      td(a.raised_at.replace("T", " ").slice(0, 19)), el("td", { class: "alarm-state" }, a.state), action);
    return tr;
  }));
}

function renderStations() {
  const list = [...state.stations.values()].sort((a, b) => a.code.localeCompare(b.code));
  $("stations").tBodies[0].replaceChildren(...list.map((s) => {
    const live = s.live || {};
    const tr = el("tr", { "data-station": s.code });
    const action = el("td");
    if (canOperate() && s.in_store) {
      const b = el("button", { type: "button" }, s.enabled ? "Disable" : "Enable");
      b.addEventListener("click", () => setStationEnabled(s.code, !s.enabled));
      action.append(b);
    }
    tr.append(td(s.code), td(String(s.rtcm_station_id ?? "–")), td(fmt(s.along_km, 2), "num"),
      td(s.enabled === false ? "disabled" : live.up ? "up" : "down"), td(String(live.satellites ?? "–"), "num"),
      td(fmt(live.last_data_age_s, 1), "num"), td(s.enabled === false ? "no" : "yes"), action);
    return tr;
  }));
}

// ---- start -------------------------------------------------------------------------------------------

async function start() {
  try { state.me = await api("GET", "/api/auth/me"); } catch (e) { return; }
  $("login").hidden = true; $("main").hidden = false; $("logout").hidden = false;
  $("whoami").textContent = state.me.name + " (" + state.me.role + ")";
  await Promise.all([refreshStations(), refreshAlarms(), refreshAudit()]);
  connectFeed();
}

function boot() {
  $("login-form").addEventListener("submit", login);
  $("logout").addEventListener("click", () => logout(true));
  // A link with #token=... (the state file's bootstrap token): drop it from the address bar at once and
  // trade it for a session token of the page's own, so that "Log out" never revokes the bootstrap token.
  const m = location.hash.match(/token=([^&]+)/);
  if (m) history.replaceState(null, "", location.pathname);
  setInterval(() => { if (state.me) refreshAlarms(); }, ALARM_REFRESH_MS);
  setInterval(() => { if (state.me) refreshStations(); }, STATIONS_REFRESH_MS);
  setInterval(() => { if (state.me) renderTrains(); }, POLL_INTERVAL_MS);  // keeps "updated s ago" honest
  if (m) adopt(decodeURIComponent(m[1]));
  else if (state.token) start(); else $("login").hidden = false;
}

async function adopt(linkToken) {
  try {
    const resp = await fetch("/api/auth/session", { method: "POST", headers: { "Authorization": "Bearer " + linkToken } });
    if (resp.status === 409) state.token = linkToken;  // a token that expires anyway: the page uses it as it is
    else if (!resp.ok) { $("login").hidden = false; $("login-error").textContent = "the link's token is not valid"; return; }
    else state.token = (await resp.json()).token;
    sessionStorage.setItem("augnet.token", state.token);
    await start();
  } catch (e) { $("login").hidden = false; $("login-error").textContent = String(e); }
}

boot();
