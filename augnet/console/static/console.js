// augnet console page: no framework, no external assets.
// Live state arrives over the websocket /api/live (a snapshot, then events); when the socket cannot be
// kept open the page polls /api/live/snapshot instead and retries the socket. Alarms, stations, the
// quality history and the audit log are read over the REST API. The line diagram, the map and the history
// charts are inline SVG drawn here. Every value from the server is set with textContent, never HTML.
"use strict";

const POLL_INTERVAL_MS = 1000;        // snapshot polling while the websocket is down
const WS_RETRY_MS = 5000;             // then try the websocket again
const ALARM_REFRESH_MS = 2000;        // alarms are raised in the store by the system: poll them
const STATIONS_REFRESH_MS = 5000;     // registry and along-track positions of stations
const AUDIT_ROWS = 15;
const SECTIONS_REFRESH_MS = 2000;     // the section register (/api/sections): its changes reach the store every 1 s
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
  geo: null,             // the map's projection (geoProjection), from the stations and the line
  history: null,         // the last /api/history/series answer
  sections: null,        // the last /api/sections answer
  historyTimer: null,
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
  clearTimeout(state.pollTimer); clearTimeout(state.historyTimer);
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
  cur.lat_deg = st.lat_deg; cur.lon_deg = st.lon_deg;
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

async function refreshSections() {
  // re-drawn only when the picture changed: a re-draw replaces the buttons under a dispatcher's pointer
  try {
    const s = await api("GET", "/api/sections");
    const key = JSON.stringify(s);
    if (key === state.sectionsKey) return;
    state.sections = s;
    state.sectionsKey = key;
    renderSections();
  } catch (e) { console.warn(e); }
}

// The dispatcher's actions (each needs the reason typed below the view; audited by the server).
async function dispatcherAction(path, body) {
  const reason = $("section-reason").value.trim();
  $("section-error").textContent = "";
  if (!reason) { $("section-error").textContent = "a dispatcher's change needs a reason"; return; }
  try {
    await api("POST", path, Object.assign({ reason }, body));
    $("section-reason").value = "";
  } catch (e) { $("section-error").textContent = String(e); }
  await Promise.all([refreshSections(), refreshAudit()]);
}

// Train `tid` one place towards the exit (swapped with the train ahead).
function moveAhead(sec, tid) {
  const order = sec.trains.map((t) => t.train_id);
  const i = order.indexOf(tid);
  if (i <= 0) return;
  [order[i - 1], order[i]] = [order[i], order[i - 1]];
  return dispatcherAction("/api/sections/" + sec.section + "/" + sec.direction + "/reorder", { order });
}

function renderSections() {
  const s = state.sections;
  if (!s) return;
  const total = s.sections.reduce((n, x) => n + x.trains.length, 0);
  $("sections-caption").textContent = "(" + total + " trains in " + s.sections.length / 2 + " sections" +
    (s.live ? "" : ", stored picture") + ")";
  const rows = [];
  for (const dir of ["up", "down"]) {
    const row = el("div", { class: "section-row", "data-direction": dir });
    row.append(el("span", { class: "section-dir" }, dir === "up" ? "up \u2192" : "\u2190 down"));
    const secs = s.sections.filter((x) => x.direction === dir).sort((a, b) => a.section - b.section);
    secs.forEach((sec) => {
      const st = (s.stations || []).find((x) => sec.km_begin != null && Math.abs(x.km_end - sec.km_begin) < 1e-6);
      if (st) {
        const inside = Object.entries(s.in_station || {}).filter(([, v]) => v.station === st.name).map(([t]) => t);
        row.append(el("span", { class: "section-station", "data-station": st.name },
          st.name + (inside.length ? " [" + inside.join(", ") + "]" : "")));
      }
      const box = el("div", { class: "section-box", "data-section": String(sec.section), "data-direction": dir });
      const km = sec.km_begin == null ? "" : " km " + fmt(sec.km_begin, 1) + "\u2013" + fmt(sec.km_end, 1);
      box.append(el("div", { class: "section-name" }, "S" + sec.section + km));
      const list = el("ol", { class: "section-trains" });
      // drawn in the direction of travel: up runs left to right, so its front train is drawn last
      const drawn = dir === "up" ? [...sec.trains].reverse() : sec.trains;
      for (const t of drawn) {
        const pos = sec.trains.indexOf(t);
        const li = el("li", { class: "section-train", "data-train": t.train_id, "data-position": String(pos),
          title: "track " + t.track + ", " + fmt(t.speed_m_s * 3.6, 0) + " km/h, length " + fmt(t.length_m, 0) +
            " m, integrity " + t.integrity + ", corr. age " + fmt(t.correction_age_s, 1) + " s, PL along " +
            fmt(t.along_pl_m, 2) + " / cross " + fmt(t.cross_pl_m, 2) + " m" });
        li.append(el("span", { class: "train-id" }, t.train_id), el("span", { class: "muted" }, " km " + fmt(t.km, 3)));
        if (pos > 0 && canOperate() && s.live) {
          const b = el("button", { type: "button", class: "move-ahead", "data-train": t.train_id,
            title: "dispatcher: move one place towards the exit" }, "ahead");
          b.addEventListener("click", () => moveAhead(sec, t.train_id));
          li.append(b);
        }
        if (canOperate() && s.live) {
          const w = el("button", { type: "button", class: "withdraw", "data-train": t.train_id,
            title: "dispatcher: take the train off the register" }, "withdraw");
          w.addEventListener("click", () => dispatcherAction(
            "/api/sections/" + sec.section + "/" + sec.direction + "/withdraw", { train_id: t.train_id }));
          li.append(w);
        }
        list.append(li);
      }
      box.append(list);
      row.append(box);
    });
    rows.push(row);
  }
  const waiting = el("div", { id: "sections-waiting", class: "muted" });
  if ((s.waiting || []).length) {
    waiting.append("waiting for a dispatcher's admission: ");
    for (const tid of s.waiting) {
      const span = el("span", { class: "section-train", "data-waiting": tid }, tid);
      if (canOperate()) {
        const b = el("button", { type: "button", class: "admit", "data-train": tid }, "admit");
        b.addEventListener("click", () => dispatcherAction("/api/sections/admit", { train_id: tid }));
        span.append(b);
      }
      waiting.append(span, " ");
    }
  }
  rows.push(waiting);
  $("sections").replaceChildren(...rows);
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
  if (all) { renderSummary(); renderStatic(); renderStations(); renderGeoStatic(); }
  renderTrainMarkers(); renderTrains(); renderGeoTrains();
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

// ---- geographic view ---------------------------------------------------------------------------------
// Stations, baselines and trains on a local equirectangular projection of their WGS84 positions (x east,
// y north, km from the centre of the stations' and the line's extent): over a line a few hundred km long
// its distortion is far below a marker's size, and it needs no tile server.

const EARTH_RADIUS_KM = 6378.137;  // WGS84 semi-major axis
const GEO = { width: 1000, height: 520, margin: 48, stationR: 9, trainR: 7, labelGap: 4 };
const SCALE_BAR_KM = [0.1, 0.2, 0.5, 1, 2, 5, 10, 20, 50, 100, 200, 500, 1000];
const SCALE_BAR_MAX_PX = 160;

function geoProjection() {
  const pts = [];
  for (const p of (state.line && state.line.polyline) || []) pts.push([p[0], p[1]]);
  for (const s of state.stations.values()) if (s.lat_deg != null && s.lon_deg != null) pts.push([s.lat_deg, s.lon_deg]);
  if (!pts.length) for (const t of state.trains.values()) pts.push([t.lat_deg, t.lon_deg]);
  if (!pts.length) return null;
  const lats = pts.map((p) => p[0]), lons = pts.map((p) => p[1]);
  const lat0 = (Math.min(...lats) + Math.max(...lats)) / 2, lon0 = (Math.min(...lons) + Math.max(...lons)) / 2;
  const k = EARTH_RADIUS_KM * Math.PI / 180, cosLat0 = Math.cos(lat0 * Math.PI / 180);
  const xy = (lat, lon) => [(lon - lon0) * k * cosLat0, (lat - lat0) * k];
  const km = pts.map((p) => xy(p[0], p[1]));
  const spanX = Math.max(...km.map((p) => Math.abs(p[0]))) * 2, spanY = Math.max(...km.map((p) => Math.abs(p[1]))) * 2;
  const scale = Math.min((GEO.width - 2 * GEO.margin) / Math.max(spanX, 1e-3), (GEO.height - 2 * GEO.margin) / Math.max(spanY, 1e-3));
  const pxPerKm = Math.min(scale, 2000);  // one station alone: a sensible zoom, not an infinite one
  const project = (lat, lon) => {
    const [x, y] = xy(lat, lon);
    return [GEO.width / 2 + x * pxPerKm, GEO.height / 2 - y * pxPerKm];
  };
  return { project, pxPerKm, lat0, lon0 };
}

function fixedFractionColour(f) {  // 0 red, 0.5 yellow, 1 green: a hue ramp
  const x = Math.min(Math.max(Number(f) || 0, 0), 1);
  return `hsl(${Math.round(120 * x)}, 70%, ${x > 0.75 ? 32 : 42}%)`;
}

function renderGeoStatic() {
  const proj = geoProjection();
  state.geo = proj;
  if (!proj) { for (const id of ["geo-line", "geo-baselines", "geo-stations", "geo-furniture"]) $(id).replaceChildren(); return; }
  const poly = ((state.line && state.line.polyline) || []).map((p) => proj.project(p[0], p[1]));
  $("geo-line").replaceChildren(...(poly.length > 1 ? [svg("path", { class: "geo-line",
    d: "M " + poly.map((p) => p[0].toFixed(1) + " " + p[1].toFixed(1)).join(" L ") })] : []));
  const at = new Map();
  const st = [];
  for (const s of [...state.stations.values()].sort((a, b) => a.code.localeCompare(b.code))) {
    if (s.lat_deg == null || s.lon_deg == null) continue;
    const [x, y] = proj.project(s.lat_deg, s.lon_deg);
    at.set(s.code, [x, y]);
    const live = s.live || {};
    const cls = s.enabled === false ? "disabled" : live.up ? "up" : "down";
    const g = svg("g", { class: "geo-station " + cls, "data-station": s.code, "data-x": x.toFixed(1), "data-y": y.toFixed(1),
      transform: `translate(${x.toFixed(1)},${y.toFixed(1)})` });
    g.append(svg("polygon", { points: "0,-9 8,6 -8,6" }), svg("title", {}, `${s.code}: ${cls}, ${fmt(s.lat_deg, 5)}°, ${fmt(s.lon_deg, 5)}°`));
    st.push(g);
  }
  $("geo-stations").replaceChildren(...st);
  const bl = [];
  for (const b of state.baselines) {
    const pa = at.get(b.a), pb = at.get(b.b);
    if (!pa || !pb) continue;
    const attrs = { class: "geo-baseline " + b.state, "data-baseline": b.a + "-" + b.b, "data-fixed-fraction": String(b.fixed_fraction),
      x1: pa[0].toFixed(1), y1: pa[1].toFixed(1), x2: pb[0].toFixed(1), y2: pb[1].toFixed(1) };
    if (b.state !== "none") attrs.stroke = fixedFractionColour(b.fixed_fraction);
    const line = svg("line", attrs);
    line.append(svg("title", {}, `${b.a}–${b.b} ${fmt(b.length_km, 1)} km: fixed ${fmt(100 * b.fixed_fraction, 0)} %`));
    bl.push(line);
  }
  $("geo-baselines").replaceChildren(...bl);
  renderGeoFurniture(proj);
  $("geo-caption").textContent = `centre ${fmt(proj.lat0, 3)}° ${fmt(proj.lon0, 3)}° · equirectangular`;
}

function renderGeoFurniture(proj) {
  const km = [...SCALE_BAR_KM].reverse().find((k) => k * proj.pxPerKm <= SCALE_BAR_MAX_PX) || SCALE_BAR_KM[0];
  const len = km * proj.pxPerKm, x0 = 20, y0 = GEO.height - 20;
  const bar = svg("g", { class: "furniture", "data-scale-km": String(km), "data-scale-px": len.toFixed(1) });
  bar.append(svg("path", { d: `M ${x0} ${y0 - 6} L ${x0} ${y0} L ${(x0 + len).toFixed(1)} ${y0} L ${(x0 + len).toFixed(1)} ${y0 - 6}` }),
    svg("text", { x: x0 + len / 2, y: y0 - 9, "text-anchor": "middle" }, km + " km"));
  const nx = GEO.width - 30, ny = 22;
  const north = svg("g", { class: "furniture north" });
  north.append(svg("polygon", { points: `${nx},${ny} ${nx - 8},${ny + 22} ${nx},${ny + 16} ${nx + 8},${ny + 22}` }),
    svg("text", { x: nx, y: ny + 38, "text-anchor": "middle" }, "N"));
  $("geo-furniture").replaceChildren(bar, north);
}

function renderGeoTrains() {
  const proj = state.geo;
  const layer = $("geo-trains");
  if (!proj) { layer.replaceChildren(); $("geo-labels").replaceChildren(); return; }
  const seen = new Set();
  for (const t of state.trains.values()) {
    if (t.lat_deg == null || t.lon_deg == null) continue;
    seen.add(t.id);
    let g = layer.querySelector(`g[data-train="${CSS.escape(t.id)}"]`);
    if (!g) {
      g = svg("g", { "data-train": t.id });
      g.append(svg("circle", { r: GEO.trainR }), svg("title"));
      layer.append(g);
    }
    const [x, y] = proj.project(t.lat_deg, t.lon_deg);
    g.setAttribute("class", "geo-train " + t.fix_state);
    g.setAttribute("transform", `translate(${x.toFixed(1)},${y.toFixed(1)})`);
    g.setAttribute("data-x", x.toFixed(1)); g.setAttribute("data-y", y.toFixed(1));
    g.querySelector("title").textContent = `${t.id}: ${t.fix_state}, ${fmt(t.lat_deg, 6)}°, ${fmt(t.lon_deg, 6)}°`;
  }
  for (const g of [...layer.children]) if (!seen.has(g.getAttribute("data-train"))) g.remove();
  placeGeoLabels();
}

// Labels next to their markers without overlapping one another or any marker: each label tries eight
// places around its marker, then the same farther out (with a leader line); the first free one wins, else
// the least covered one. Stations are placed first (they do not move), then trains.
const LABEL_SLOTS = [[1, 0], [-1, 0], [0, -1], [0, 1], [1, -1], [1, 1], [-1, -1], [-1, 1]];
const LABEL_RINGS = [1, 2.2, 3.6];
// Placement is quadratic in labels: past this many trains (a load test's fleet) they keep their tooltip only.
const MAX_TRAIN_LABELS = 100;

function overlapArea(a, b) {
  const w = Math.min(a.x + a.w, b.x + b.w) - Math.max(a.x, b.x), h = Math.min(a.y + a.h, b.y + b.h) - Math.max(a.y, b.y);
  return w > 0 && h > 0 ? w * h : 0;
}

function placeGeoLabels() {
  const layer = $("geo-labels");
  layer.replaceChildren();
  const marks = [];
  const obstacles = [];
  for (const g of $("geo-stations").children) marks.push({ g, kind: "station", r: GEO.stationR, text: g.getAttribute("data-station") });
  const trains = [...$("geo-trains").children];
  for (const g of trains.length <= MAX_TRAIN_LABELS ? trains : []) marks.push({ g, kind: "train", r: GEO.trainR, text: g.getAttribute("data-train") });
  for (const m of marks) {
    m.x = parseFloat(m.g.getAttribute("data-x")); m.y = parseFloat(m.g.getAttribute("data-y"));
    obstacles.push({ x: m.x - m.r, y: m.y - m.r, w: 2 * m.r, h: 2 * m.r });
  }
  for (const g of trains.length > MAX_TRAIN_LABELS ? trains : []) {  // unlabelled trains still block labels
    const x = parseFloat(g.getAttribute("data-x")), y = parseFloat(g.getAttribute("data-y"));
    obstacles.push({ x: x - GEO.trainR, y: y - GEO.trainR, w: 2 * GEO.trainR, h: 2 * GEO.trainR });
  }
  const out = [];
  for (const m of marks) {
    const t = svg("text", { class: "label-" + m.kind, "data-label-for": m.kind + ":" + m.text, x: 0, y: 0 }, m.text);
    layer.append(t);  // measured where it is drawn (font as styled)
    out.push([m, t]);
  }
  const placed = [];
  for (const [m, t] of out) {
    const bb = t.getBBox();
    const w = bb.width, h = bb.height, ascent = -bb.y;  // bb.y: the box's top relative to the baseline
    let best = null;
    search: for (const ring of LABEL_RINGS) {
      for (const [dx, dy] of LABEL_SLOTS) {
        const d = (m.r + GEO.labelGap) * ring;
        const cx = m.x + dx * d, cy = m.y + dy * d;
        const box = { x: dx > 0 ? cx : dx < 0 ? cx - w : cx - w / 2, y: dy > 0 ? cy : dy < 0 ? cy - h : cy - h / 2, w, h };
        const inside = box.x >= 0 && box.y >= 0 && box.x + w <= GEO.width && box.y + h <= GEO.height;
        let cover = inside ? 0 : 1e9;
        for (const o of obstacles) cover += overlapArea(box, o);
        for (const p of placed) cover += overlapArea(box, p);
        if (best === null || cover < best.cover) best = { box, cover, ring };
        if (cover === 0) break search;
      }
    }
    placed.push(best.box);
    t.setAttribute("x", best.box.x.toFixed(1));
    t.setAttribute("y", (best.box.y + ascent).toFixed(1));
    if (best.ring > 1) {
      const lx = Math.min(Math.max(m.x, best.box.x), best.box.x + w), ly = Math.min(Math.max(m.y, best.box.y), best.box.y + h);
      layer.append(svg("line", { class: "leader", x1: m.x.toFixed(1), y1: m.y.toFixed(1), x2: lx.toFixed(1), y2: ly.toFixed(1) }));
    }
  }
}

// ---- history charts ----------------------------------------------------------------------------------
// Series of the store's quality history (GET /api/history/series: the server downsamples each into at most
// HISTORY_POINTS buckets of mean, min and max), drawn as inline SVG: the mean as a line, min..max as a band.

const HISTORY_POINTS = 240;
const HISTORY_REFRESH_MS = 10000;  // the history's cadence (persistence.QUALITY_INTERVAL_S): no sooner
const CHART = { width: 460, height: 210, left: 50, right: 12, top: 10, bottom: 40, tickGapPx: 14 };
const PALETTE = ["#1565c0", "#2e7d32", "#c62828", "#ef8f00", "#6a1b9a", "#00838f", "#5d4037", "#ad1457", "#558b2f", "#37474f"];
const CHARTS = {
  fixed_fraction: { axis: "fixed %", scale: 100, max: 100 },
  correction_age_p99: { axis: "age s", scale: 1, max: null },
  trains: { axis: "trains", scale: 1, max: null, integer: true },
  station_data_age: { axis: "age s", scale: 1, max: null },
};
const TIME_STEPS_S = [60, 120, 300, 600, 900, 1800, 3600, 7200, 10800, 21600, 43200, 86400, 172800];
const GAP_BUCKETS = 2.5;  // a series is broken where consecutive points are farther apart than this many buckets

async function refreshHistory() {
  clearTimeout(state.historyTimer);
  const windowS = Number($("history-window").value);
  try {
    const h = await api("GET", `/api/history/series?window_s=${windowS}&points=${HISTORY_POINTS}`);
    state.history = h;
    renderHistory();
  } catch (e) { console.warn(e); }
  // again when a new point is due: every 10 s for the last hour, every 42 min for a week (a week's read
  // costs the store about a second: docs/measured.md)
  if (state.me) state.historyTimer = setTimeout(refreshHistory, Math.max(HISTORY_REFRESH_MS, 1000 * windowS / HISTORY_POINTS));
}

function niceStep(span, maxTicks) {
  const raw = span / Math.max(maxTicks, 1), mag = Math.pow(10, Math.floor(Math.log10(raw)));
  for (const m of [1, 2, 2.5, 5, 10]) if (m * mag >= raw) return m * mag;
  return 10 * mag;
}

function utcLabel(tUnix, stepS) {
  const iso = new Date(tUnix * 1000).toISOString();  // always UTC
  return stepS >= 86400 ? iso.slice(5, 10) : stepS >= 43200 ? iso.slice(5, 10) + " " + iso.slice(11, 16) : iso.slice(11, 16);
}

function textWidth(host, s) {  // a label's drawn width in the chart's units
  const t = svg("text", { x: 0, y: -100 }, s);
  host.append(t);
  const w = t.getBBox().width;
  t.remove();
  return w;
}

function renderHistory() {
  const h = state.history;
  if (!h) return;
  const since = Date.parse(h.since) / 1000, until = Date.parse(h.until) / 1000;
  $("history-caption").textContent = `${h.since.slice(0, 16).replace("T", " ")} – ${h.until.slice(0, 16).replace("T", " ")} UTC · a point per ${fmt(h.bucket_s, 0)} s`;
  for (const kind of Object.keys(CHARTS)) {
    drawChart(kind, h.series.filter((s) => s.kind === kind).sort((a, b) => a.label.localeCompare(b.label)), since, until, h.bucket_s);
  }
}

function drawChart(kind, list, since, until, bucketS) {
  const cfg = CHARTS[kind], host = $("chart-" + kind);
  host.replaceChildren();
  const x0 = CHART.left, x1 = CHART.width - CHART.right, y0 = CHART.height - CHART.bottom, y1 = CHART.top;
  const xOfT = (t) => x0 + (x1 - x0) * (t - since) / (until - since);
  let top = cfg.max;
  if (top === null) {
    top = 0;
    for (const s of list) for (const p of s.points) top = Math.max(top, p[3] * cfg.scale);
    top = top > 0 ? top * 1.1 : 1;
  }
  const yStep = cfg.integer ? Math.max(1, Math.ceil(niceStep(top, Math.floor((y0 - y1) / 22)))) : niceStep(top, Math.floor((y0 - y1) / 22));
  top = Math.ceil(top / yStep - 1e-9) * yStep;
  const yOf = (v) => y0 - (y0 - y1) * Math.min(Math.max(v * cfg.scale / top, 0), 1.02);
  const nodes = [];
  const digits = yStep >= 1 ? 0 : yStep >= 0.1 ? 1 : 2;
  for (let v = 0; v <= top + 1e-9; v += yStep) {  // value axis: labels a row (>= 22 units) apart
    const y = y0 - (y0 - y1) * v / top;
    nodes.push(svg("line", { class: "grid", x1: x0, x2: x1, y1: y.toFixed(1), y2: y.toFixed(1) }),
      svg("text", { class: "tick-y", x: x0 - 4, y: (y + 4).toFixed(1), "text-anchor": "end" }, v.toFixed(digits)));
  }
  nodes.push(svg("text", { class: "axis-title", x: 12, y: (y0 + y1) / 2, "text-anchor": "middle",
    transform: `rotate(-90 12 ${((y0 + y1) / 2).toFixed(1)})` }, cfg.axis));
  // time axis: the smallest step whose labels, measured in their format for that step, fit side by side
  let stepS = TIME_STEPS_S[TIME_STEPS_S.length - 1], labelW = 0;
  for (const s of TIME_STEPS_S) {
    const w = textWidth(host, utcLabel(until, s)) + CHART.tickGapPx;
    if ((until - since) / s <= Math.max(1, Math.floor((x1 - x0) / w))) { stepS = s; labelW = w; break; }
  }
  if (!labelW) labelW = textWidth(host, utcLabel(until, stepS)) + CHART.tickGapPx;
  for (let t = Math.ceil(since / stepS) * stepS; t <= until; t += stepS) {
    const x = xOfT(t);
    if (x - x0 < labelW / 2 - CHART.tickGapPx / 2 || x1 - x < labelW / 2 - CHART.tickGapPx / 2) continue;  // would poke out
    nodes.push(svg("line", { class: "axis", x1: x.toFixed(1), x2: x.toFixed(1), y1: y0, y2: y0 + 4 }),
      svg("text", { class: "tick-x", x: x.toFixed(1), y: y0 + 16, "text-anchor": "middle" }, utcLabel(t, stepS)));
  }
  nodes.push(svg("text", { class: "axis-title", x: (x0 + x1) / 2, y: y0 + 32, "text-anchor": "middle" }, "time (UTC)"));
  nodes.push(svg("line", { class: "axis", x1: x0, x2: x1, y1: y0, y2: y0 }), svg("line", { class: "axis", x1: x0, x2: x0, y1: y1, y2: y0 }));
  const legend = [];
  list.forEach((s, i) => {
    const colour = PALETTE[i % PALETTE.length];
    const runs = [[]];  // split at gaps
    s.points.forEach((p, j) => {
      if (j > 0 && p[0] - s.points[j - 1][0] > GAP_BUCKETS * Math.max(bucketS, 10)) runs.push([]);
      runs[runs.length - 1].push(p);
    });
    const g = svg("g", { class: "series-group", "data-series": s.subject, "data-points": String(s.points.length) });
    for (const run of runs) {
      if (run.length > 1) {
        const upper = run.map((p) => xOfT(p[0]).toFixed(1) + "," + yOf(p[3]).toFixed(1));
        const lower = run.slice().reverse().map((p) => xOfT(p[0]).toFixed(1) + "," + yOf(p[2]).toFixed(1));
        g.append(svg("polygon", { class: "band", fill: colour, points: upper.concat(lower).join(" ") }));
      }
      g.append(svg("polyline", { class: "series", stroke: colour, "data-points": String(run.length),
        points: run.map((p) => xOfT(p[0]).toFixed(1) + "," + yOf(p[1]).toFixed(1)).join(" ") }));
      if (run.length === 1) g.append(svg("circle", { r: 2, fill: colour, cx: xOfT(run[0][0]).toFixed(1), cy: yOf(run[0][1]).toFixed(1) }));
    }
    const last = s.points[s.points.length - 1];
    g.append(svg("title", {}, `${s.label}: ${last ? fmt(last[1] * cfg.scale, 2) : "–"} ${cfg.axis} at ${last ? new Date(last[0] * 1000).toISOString().slice(11, 19) : "–"} UTC`));
    nodes.push(g);
    const item = el("span", { "data-series": s.subject });
    const sw = svg("svg", { viewBox: "0 0 10 5" });
    sw.append(svg("rect", { width: 10, height: 5, fill: colour }));
    item.append(sw, s.label);
    legend.push(item);
  });
  if (!list.length) nodes.push(svg("text", { class: "empty", x: (x0 + x1) / 2, y: (y0 + y1) / 2, "text-anchor": "middle" }, "no data in this window"));
  host.append(...nodes);
  $("legend-" + kind).replaceChildren(...legend);
}

// ---- start -------------------------------------------------------------------------------------------

async function start() {
  try { state.me = await api("GET", "/api/auth/me"); } catch (e) { return; }
  $("login").hidden = true; $("main").hidden = false; $("logout").hidden = false;
  $("whoami").textContent = state.me.name + " (" + state.me.role + ")";
  await Promise.all([refreshStations(), refreshAlarms(), refreshAudit(), refreshHistory(), refreshSections()]);
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
  setInterval(() => { if (state.me) refreshSections(); }, SECTIONS_REFRESH_MS);
  $("history-window").addEventListener("change", () => { if (state.me) refreshHistory(); });
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
