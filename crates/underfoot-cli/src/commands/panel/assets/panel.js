// The control panel's page: a WebSocket of status (about 50 a second) drawn as meters
// and timelines, and the JSON API for steering, the library and fitting. Plain
// JavaScript, no build step, no network beyond the panel itself.
"use strict";

const TOKEN = document.querySelector('meta[name="underfoot-token"]').content;
const HISTORY_S = 10;
// Bottom of the level meters and timelines: a step's vibration is often 40-60 dB below
// full scale, its ring further down.
const FLOOR_DB = -90;
// Meters hold their peaks and fall back at this rate, as a studio meter does: each status
// covers only 20 ms, and a strike lasts about that long.
const FALL_DB_PER_S = 30;

const $ = (sel, root = document) => root.querySelector(sel);
const el = (tag, props = {}, ...kids) => {
  const e = Object.assign(document.createElement(tag), props);
  for (const k of kids) e.append(k);
  return e;
};
const db = (x) => (x > 0 ? 20 * Math.log10(x) : -Infinity);
const fmtDb = (d) => (d > FLOOR_DB ? d.toFixed(1) : `< ${FLOOR_DB}`);
const held = (previous, value, dt) => Math.max(value, previous - FALL_DB_PER_S * dt);
const pct = (d) => `${Math.max(0, Math.min(100, ((d - FLOOR_DB) / -FLOOR_DB) * 100))}%`;

// Every request that changes something carries the token; the server also checks the
// page's origin.
async function api(method, path, body, raw) {
  const headers = { "X-Underfoot-Token": TOKEN };
  let payload;
  if (raw !== undefined) {
    headers["Content-Type"] = "application/octet-stream";
    payload = raw;
  } else if (body !== undefined) {
    headers["Content-Type"] = "application/json";
    payload = JSON.stringify(body);
  }
  const response = await fetch(path, { method, headers, body: payload });
  const text = await response.text();
  let data = null;
  try { data = text ? JSON.parse(text) : null; } catch (_) { data = { error: text }; }
  if (!response.ok) throw new Error((data && data.error) || `${response.status} ${response.statusText}`);
  return data;
}

const view = {
  channels: [],        // per channel: { root, history: [], markers: [] }
  catalog: [],         // /api/library's materials
  catalogVersion: -1,
  ceilingDb: 0,
  strikesBase: null,   // strikes when the page first heard the engine
  markersSeen: 0,
  drawing: false,      // a frame is asked for to draw the timelines
  elapsed: 0,          // the session's time, from its last status
  notes: [],           // markers put into the record from this page: session times
  recording: null,     // what the trial bar last showed
  choosing: false,     // the session form is open (and filled) for the next session's choice
  offers: null,        // /api/session/options, once asked

};

function banner(text, bad) {
  const b = $("#banner");
  b.hidden = !text;
  b.textContent = text || "";
  b.className = bad ? "bad" : "";
}

function setLink(text, cls) {
  const l = $("#link");
  l.textContent = text;
  l.className = `pill ${cls}`;
}

// --- live status -----------------------------------------------------------------------

function connect() {
  const query = new URLSearchParams(location.search).get("token");
  const url = `ws://${location.host}/api/ws${query ? `?token=${encodeURIComponent(query)}` : ""}`;
  const ws = new WebSocket(url);
  ws.onopen = () => setLink("connected", "ok");
  ws.onmessage = (m) => update(JSON.parse(m.data));
  ws.onclose = () => {
    // The panel may be restarting, or the network blinked: subscribe again.
    setLink("reconnecting…", "warn");
    setTimeout(connect, 1000);
  };
}

function update(s) {
  view.ceilingDb = s.ceiling_db;
  view.elapsed = s.elapsed_s;
  setRecording(s.record, s.state === "running");
  setSettings(s);
  $("#session").textContent = s.session;
  $("#elapsed").textContent = `${s.elapsed_s.toFixed(1)} s`;
  $("#events").textContent = s.input.events;
  $("#rejected").textContent = s.input.rejected;
  $("#lost").textContent = s.input.lost;
  $("#late-buffers").textContent = s.engine.late_buffers;
  $("#late").textContent = s.engine.late_readings;
  $("#non-finite").textContent = s.engine.non_finite;
  $("#latency").textContent = s.latency_ms == null ? "–" : `${s.latency_ms.toFixed(1)} ms`;
  if (s.state === "starting") {
    $("#restart").hidden = true;
    setLink("starting", "warn");
    banner("The session is starting: preparing the materials and opening the devices.", false);
  } else if (s.state !== "running") {
    $("#stop").disabled = true;
    $("#restart").hidden = false;
    setLink("engine stopped", "bad");
    banner(`The engine has stopped: ${s.reason}. "Start" starts a new session with the input, output and library under Session.`, s.state === "failed");
  } else {
    $("#stop").disabled = false;
    $("#restart").hidden = true;
    setLink("live", "ok");
    banner(s.input.link !== "open" ? `Input ${s.input.link}: the output fades to silence until it comes back.` : "");
  }
  if (s.catalog_version !== view.catalogVersion) {
    view.catalogVersion = s.catalog_version;
    loadLibrary();
  }
  while (view.channels.length < s.channels.length) addChannel(view.channels.length);
  const total = s.channels.reduce((a, c) => a + c.strikes, 0);
  if (view.strikesBase === null) view.strikesBase = total;
  s.channels.forEach((c, i) => updateChannel(view.channels[i], c, s.elapsed_s, s.state === "running"));
  document.body.dataset.markers = view.markersSeen;
  document.body.dataset.strikesBase = view.strikesBase;
  document.body.dataset.strikes = total;
}

function addChannel(index) {
  const root = $("#channel-template").content.firstElementChild.cloneNode(true);
  root.dataset.channel = index;
  $("h3", root).textContent = `Channel ${index + 1}`;
  const ch = {
    root, history: [], markers: [], strikes: null, select: $("select.material", root),
    last: null, peak: -Infinity, rms: -Infinity, drive: -Infinity, gr: 0,
  };
  ch.select.addEventListener("change", () => steer(index, ch));
  for (const r of root.querySelectorAll(".model input")) {
    r.name = `model-${index}`;
    r.addEventListener("change", () => steer(index, ch));
  }
  const gain = $(".gain", root);
  gain.addEventListener("input", () => { $(".gain-value", root).textContent = `${gain.value} dB`; });
  gain.addEventListener("change", () =>
    api("POST", `/api/v2/channels/${index + 1}/gain`, { trim_db: Number(gain.value) }).catch((e) => banner(`gain: ${e.message}`, true)));
  $("#channels").append(root);
  view.channels.push(ch);
  fillMaterials(ch);
}

function updateChannel(ch, c, t, running) {
  const root = ch.root;
  root.classList.toggle("stopped", !running);
  const material = c.material ? `${c.material}${c.model === "physical" ? " (physical model)" : ""}` : "no material";
  $("h3", root).textContent = `Channel ${Number(root.dataset.channel) + 1}: ${material}`;
  const wd = $(".watchdog", root);
  // A session that has ended plays nothing, whatever its last status said.
  const live = running && c.live;
  wd.textContent = !running ? "stopped" : live ? "sensor input: live" : "no input: faded";
  wd.className = `watchdog pill ${!running ? "bad" : live ? "ok" : "warn"}`;
  if (!running) {
    ch.peak = ch.rms = ch.drive = -Infinity;
    ch.gr = 0;
    c = { ...c, peak_dbfs: null, rms_dbfs: null, drive: 0, gain_reduction_db: 0, force_n: 0, sensors: c.sensors.map(() => 0) };
  }
  $(".strikes", root).textContent = `${c.strikes} strikes`;
  // Force per sensor: bars scaled to the body weight.
  const bars = $(".force .bars", root);
  while (bars.children.length < c.sensors.length) bars.append(el("i"));
  while (bars.children.length > Math.max(1, c.sensors.length)) bars.lastChild.remove();
  c.sensors.forEach((f, i) => bars.children[i].style.setProperty("--w", `${Math.min(100, (f / c.weight_n) * 100)}%`));
  $(".force .value", root).textContent = `${c.force_n.toFixed(0)} N`;
  const dt = ch.last === null ? 0 : Math.max(0, t - ch.last);
  ch.last = t;
  ch.peak = held(ch.peak, c.peak_dbfs ?? -Infinity, dt);
  ch.rms = held(ch.rms, c.rms_dbfs ?? -Infinity, dt);
  ch.drive = held(ch.drive, db(c.drive), dt);
  ch.gr = Math.max(c.gain_reduction_db, ch.gr - FALL_DB_PER_S * dt, 0);
  $(".drive i", root).style.width = pct(ch.drive);
  $(".drive .value", root).textContent = `${fmtDb(ch.drive)} dB`;
  $(".drive .value", root).title = "the filter's excitation, peak, dB relative to a nominal step";
  $(".out i.rms", root).style.width = pct(ch.rms);
  $(".out i.peak", root).style.width = pct(ch.peak);
  $(".out b.ceiling", root).style.left = pct(view.ceilingDb);
  $(".out .value", root).textContent = `${fmtDb(ch.peak)} pk ${fmtDb(ch.rms)} rms`;
  $(".out .value", root).title = "output peak and RMS, dBFS (held, falling 30 dB/s)";
  $(".gr i", root).style.width = `${Math.min(100, (ch.gr / 20) * 100)}%`;
  $(".gr .value", root).textContent = ch.gr > 0.05 ? `−${ch.gr.toFixed(1)} dB` : "not limiting";
  // Strike markers: one per strike the engine counted since the last status.
  if (ch.strikes !== null && c.strikes > ch.strikes) {
    for (let k = ch.strikes; k < c.strikes; k++) ch.markers.push(t);
    view.markersSeen += c.strikes - ch.strikes;
  }
  ch.strikes = c.strikes;
  ch.history.push({ t, peak: c.peak_dbfs ?? -Infinity, force: c.force_n / c.weight_n });
  while (ch.history.length && ch.history[0].t < t - HISTORY_S) ch.history.shift();
  while (ch.markers.length && ch.markers[0] < t - HISTORY_S) ch.markers.shift();
  root.dataset.markers = ch.markers.length;
  if (document.activeElement !== ch.select) selectCurrent(ch, c);
  const gain = $(".gain", root);
  if (document.activeElement !== gain) {
    gain.value = Math.round(c.trim_db);
    $(".gain-value", root).textContent = `${Math.round(c.trim_db)} dB`;
  }
  ch.now = t;
  if (!view.drawing) {
    // Statuses come faster than the screen refreshes: draw the timelines once a frame.
    view.drawing = true;
    requestAnimationFrame(() => {
      view.drawing = false;
      for (const c of view.channels) if (c.now !== undefined) drawTimeline(c, c.now);
    });
  }
}

function drawTimeline(ch, now) {
  const canvas = $("canvas", ch.root);
  const w = canvas.clientWidth || canvas.width, h = canvas.height;
  if (canvas.width !== w) canvas.width = w;
  const g = canvas.getContext("2d");
  g.clearRect(0, 0, w, h);
  const x = (t) => w - ((now - t) / HISTORY_S) * w;
  const y = (d) => h - 4 - (Math.max(0, d - FLOOR_DB) / -FLOOR_DB) * (h - 14);
  g.font = "11px system-ui, sans-serif";
  g.fillStyle = "#5e6b7d";
  g.fillText(`last 10 s: output peak (blue, ${FLOOR_DB} to 0 dBFS), force (purple), strikes (red)`, 6, 12);
  g.strokeStyle = "#e3e7ee";
  for (let s = 1; s < HISTORY_S; s++) { g.beginPath(); g.moveTo(x(now - s), 16); g.lineTo(x(now - s), h); g.stroke(); }
  g.strokeStyle = "#c62828";
  g.lineWidth = 2;
  for (const m of ch.markers) { g.beginPath(); g.moveTo(x(m), 16); g.lineTo(x(m), h); g.stroke(); }
  // The record's markers: dashed, green, through every channel.
  g.strokeStyle = "#1b7f3b";
  g.setLineDash([4, 3]);
  for (const m of view.notes) { g.beginPath(); g.moveTo(x(m), 16); g.lineTo(x(m), h); g.stroke(); }
  g.setLineDash([]);
  g.lineWidth = 1.5;
  const line = (color, value) => {
    g.strokeStyle = color;
    g.beginPath();
    ch.history.forEach((p, i) => (i ? g.lineTo : g.moveTo).call(g, x(p.t), value(p)));
    g.stroke();
  };
  line("#8a5cd0", (p) => h - 4 - Math.min(1.5, Math.max(0, p.force)) / 1.5 * (h - 14));
  line("#2757c9", (p) => y(p.peak));
}

// --- steering --------------------------------------------------------------------------

function fillMaterials(ch) {
  const keep = ch.select.value;
  ch.select.replaceChildren(...view.catalog.map((m) => el("option", { value: m.name, textContent: m.name })));
  if (keep) ch.select.value = keep;
}

function selectCurrent(ch, c) {
  if (c.material && ch.select.value !== c.material) ch.select.value = c.material;
  const entry = view.catalog.find((m) => m.name === ch.select.value);
  for (const r of ch.root.querySelectorAll(".model input")) {
    r.checked = r.value === c.model;
    r.disabled = r.value === "physical" && !(entry && entry.slots.physical != null);
  }
}

async function steer(index, ch) {
  const model = ch.root.querySelector(".model input:checked")?.value || "iir";
  const entry = view.catalog.find((m) => m.name === ch.select.value);
  const use = model === "physical" && entry && entry.slots.physical == null ? "iir" : model;
  try {
    await api("POST", `/api/v2/channels/${index + 1}/material`, { material: ch.select.value, model: use });
  } catch (e) {
    banner(`channel ${index + 1}: ${e.message}`, true);
  }
}

// --- trials and markers ----------------------------------------------------------------

function setRecording(dir, running) {
  // Redrawn only when it changes: statuses come 50 times a second.
  const key = `${dir}|${running}`;
  if (key === view.recording) return;
  view.recording = key;
  const on = Boolean(dir) && running;
  $("#record-where").textContent = dir
    ? (running ? `recording into ${dir}` : `recorded into ${dir}; the session has ended`)
    : "not recorded: start the panel with --record DIR to keep markers";
  for (const c of $("#trial-form").querySelectorAll("input, button")) c.disabled = !on;
}

async function mark(text) {
  const trial = Number($("#trial").value);
  const body = { text };
  if (Number.isInteger(trial) && trial > 0) body.trial = trial;
  for (const key of ["participant", "condition"]) {
    const v = $(`#${key}`).value.trim();
    if (v) body[key] = v;
  }
  try {
    const m = await api("POST", "/api/markers", body);
    view.notes.push(m.elapsed_s);
    const fields = [m.trial && `trial ${m.trial}`, m.participant, m.condition].filter(Boolean).join(", ");
    $("#markers").prepend(el("li", { textContent: `${m.elapsed_s.toFixed(1)} s  ${m.text}${fields ? ` (${fields})` : ""}` }));
    return true;
  } catch (e) {
    banner(`marker: ${e.message}`, true);
    return false;
  }
}

$("#trial-form").addEventListener("submit", async (e) => {
  e.preventDefault();
  const input = $("#marker-text");
  const text = input.value.trim() || `trial ${$("#trial").value}`;
  if (await mark(text)) input.value = "";
});

$("#next-trial").addEventListener("click", async () => {
  const t = $("#trial");
  t.value = String((Number(t.value) || 0) + 1);
  await mark(`trial ${t.value} starts`);
});

// The session's input, output and library: shown while it runs, chosen once it has
// ended (filled from the last session then, and left alone while the person types).
function setSettings(s) {
  const open = s.state === "ended" || s.state === "failed";
  // Filled once as the form opens; from then on the fields are the person's.
  if (open && view.choosing) return;
  view.choosing = open;
  if (open) loadOffers();
  const set = s.settings;
  const input = $("#set-input"), output = $("#set-output"), library = $("#set-library");
  input.value = set.interface ? `(the interface ${set.interface})` : set.input;
  output.value = set.output;
  library.value = set.library || "";
  input.disabled = !open || Boolean(set.interface);
  output.disabled = !open;
  library.disabled = !open || (view.offers !== null && !view.offers.files_allowed);
}

async function loadOffers() {
  try {
    view.offers = await api("GET", "/api/session/options");
  } catch (e) {
    return;
  }
  const fill = (list, items) => list.replaceChildren(...items.map((v) => el("option", { value: v })));
  fill($("#input-offers"), view.offers.inputs);
  fill($("#output-offers"), view.offers.outputs);
  if (!view.offers.files_allowed) {
    const lib = $("#set-library");
    lib.disabled = true;
    lib.title = "This panel serves other machines: its library is the command line's";
  }
}

$("#restart").addEventListener("click", () => {
  const body = {};
  if (!$("#set-input").disabled) body.input = $("#set-input").value;
  body.output = $("#set-output").value;
  if (!$("#set-library").disabled) body.library = $("#set-library").value;
  $("#restart").hidden = true;
  api("POST", "/api/session/start", body).catch((e) => {
    $("#restart").hidden = false;
    banner(`start: ${e.message}`, true);
  });
});

$("#stop").addEventListener("click", () => {
  api("POST", "/api/stop", {}).catch((e) => banner(`stop: ${e.message}`, true));
});

// --- library ---------------------------------------------------------------------------

async function loadLibrary() {
  const lib = await api("GET", "/api/library");
  view.catalog = lib.materials;
  $("#library-origin").textContent = lib.origin;
  const rows = lib.materials.map((m, i) => {
    const loo = m.leave_one_out ? m.leave_one_out.mean_lsd_db.toFixed(2) : "–";
    const phys = m.physical ? `${m.physical.kind}, ${m.physical.modes} modes, LSD ${m.physical.lsd_db.toFixed(2)} dB` : "none";
    const tr = el("tr", {},
      el("td", { textContent: m.name + (m.added ? " (fitted here)" : "") }),
      el("td", { className: "num", textContent: m.order }),
      el("td", { className: "num", textContent: m.nrmse.toFixed(4) }),
      el("td", { className: "num", textContent: m.lsd_db.toFixed(2) }),
      el("td", { className: "num", textContent: m.strikes }),
      el("td", { className: "num", textContent: loo }),
      el("td", { textContent: phys }));
    tr.dataset.material = m.name;
    tr.addEventListener("click", () => showResponse(i));
    return tr;
  });
  $("#library tbody").replaceChildren(...rows);
  for (const ch of view.channels) fillMaterials(ch);
  if (lib.materials.length && !$("#response").firstChild) showResponse(0);
}

function showResponse(i) {
  const m = view.catalog[i];
  for (const tr of document.querySelectorAll("#library tbody tr")) tr.classList.toggle("selected", tr.dataset.material === m.name);
  $("#response").replaceChildren(responsePlot(m), physicalTable(m));
}

// The physical model's parameters, as the library stores them.
function physicalTable(m) {
  const p = m.physical_model;
  if (!p) return el("p", { className: "params", textContent: `${m.name} has no physical model (its calibration failed or was not run).` });
  const fmt = (x, unit = "") => {
    if (typeof x !== "number") return String(x);
    const big = x !== 0 && (Math.abs(x) >= 1e5 || Math.abs(x) < 1e-3);
    return `${big ? x.toExponential(3).replace("e+", "e") : Number(x.toPrecision(4))}${unit}`;
  };
  const freqs = p.modes.map((mode) => mode.frequency);
  const rows = [
    ["kind", p.kind],
    ["modes", `${freqs.length}, ${fmt(Math.min(...freqs), " Hz")} to ${fmt(Math.max(...freqs), " Hz")}`],
    ["hammer mass", fmt(p.hammer.mass, " kg")],
    ["contact stiffness k", fmt(p.hammer.stiffness, " N/m^α")],
    ["contact exponent α", fmt(p.hammer.alpha)],
    ["contact damping λ", fmt(p.hammer.damping, " N·s/m^(α+1)")],
    ["strike velocity (RMS)", fmt(p.hammer.velocity, " m/s")],
  ];
  if (p.kind === "aggregate") {
    rows.push(["event-rate scale a", fmt(p.record.rate_scale)], ["fragment size spread", fmt(p.size_spread)], ["impacts in flight", fmt(p.voices)]);
  }
  rows.push(["output gain", fmt(p.output_gain)]);
  if (p.record) {
    rows.push(["calibration LSD", fmt(p.record.lsd_db, " dB")], ["onsets per strike", fmt(p.record.onsets_per_strike)], ["half-energy time", fmt(p.record.half_energy_ms, " ms")]);
  }
  return el("div", { className: "params" },
    el("h3", { textContent: `${m.name}: physical model` }),
    el("dl", {}, ...rows.flatMap(([k, v]) => [el("dt", { textContent: k }), el("dd", { textContent: v })])));
}

// Measured against model magnitude, dB on a log-frequency axis, as `fit --plot` draws it:
// the same words, the axis over the fitted band labelled at its edges, the physical
// model's calibration render beside the filter's when there is one, and the legend on
// the title's row when it fits there, else on a row of its own (never over the title or
// the curves). Text is placed at 0.6 em a character, as the CLI's figures are.
function responsePlot(m) {
  const W = 900, L = 56, R = 16, B = 44;
  const width = (text, size) => 0.6 * size * String(text).length;
  const f = m.grid_hz;
  const db = (v) => (v > 0 ? 20 * Math.log10(v) : null);
  const physical = m.physical_model && m.physical_model.record && m.physical_model.record.model.length === f.length
    ? m.physical_model.record.model.map(db) : null;
  const curves = [
    { label: "measured", values: m.measured_db, color: "#1d2430", width: 1.5 },
    { label: physical ? "IIR" : "model", values: m.model_db, color: "#c62828", width: 2 },
  ];
  if (physical) curves.push({ label: "physical", values: physical, color: "#1565c0", width: 2 });
  const title = `${m.name}: order ${m.order}, NRMSE ${m.nrmse.toFixed(4)}, LSD ${m.lsd_db.toFixed(2)} dB`
    + (physical ? `; physical LSD ${m.physical_model.record.lsd_db.toFixed(2)} dB` : "");
  const entryWidth = (c) => 26 + width(c.label, 12) + 16;
  const legendWidth = curves.reduce((w, c) => w + entryWidth(c), 0);
  const beside = L + width(title, 14) + 24 <= W - R - legendWidth;
  const T = beside ? 30 : 50, H = 300 + (T - 30);
  const ns = "http://www.w3.org/2000/svg";
  const svg = document.createElementNS(ns, "svg");
  svg.setAttribute("viewBox", `0 0 ${W} ${H}`);
  const add = (tag, attrs, text) => {
    const e = document.createElementNS(ns, tag);
    for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
    if (text !== undefined) e.textContent = text;
    svg.append(e);
    return e;
  };
  const all = curves.flatMap((c) => c.values).filter(Number.isFinite);
  const top = Math.ceil(Math.max(...all) / 5) * 5, bottom = Math.max(Math.floor(Math.min(...all) / 5) * 5, top - 90);
  const stepDb = top - bottom > 40 ? 10 : 5;
  const lf0 = Math.log10(f[0]), lf1 = Math.log10(f[f.length - 1]);
  const x = (hz) => L + ((Math.log10(hz) - lf0) / (lf1 - lf0)) * (W - L - R);
  const y = (d) => T + ((top - Math.max(bottom, d)) / (top - bottom)) * (H - T - B);
  add("text", { x: L, y: 18, "font-size": 14, "font-weight": 600 }, title);
  let lx = beside ? W - R - legendWidth : L, ly = beside ? 14 : 38;
  for (const c of curves) {
    add("line", { x1: lx, x2: lx + 20, y1: ly, y2: ly, stroke: c.color, "stroke-width": 2 });
    add("text", { x: lx + 26, y: ly + 4, "font-size": 12 }, c.label);
    lx += entryWidth(c);
  }
  for (let d = bottom; d <= top; d += stepDb) {
    add("line", { x1: L, x2: W - R, y1: y(d), y2: y(d), stroke: "#e3e7ee" });
    add("text", { x: L - 6, y: y(d) + 4, "font-size": 11, "text-anchor": "end", fill: "#5e6b7d" }, d);
  }
  // The 1-2-5 frequencies inside the band, and its edges unless one is within a factor
  // of 1.2 (their labels would collide).
  const lo = f[0], hi = f[f.length - 1];
  const ticks = [];
  for (let decade = 1; decade <= 10000; decade *= 10) {
    for (const k of [1, 2, 5]) if (k * decade >= lo * (1 - 1e-9) && k * decade <= hi * (1 + 1e-9)) ticks.push(k * decade);
  }
  for (const edge of [lo, hi]) if (ticks.every((t) => Math.max(t / edge, edge / t) >= 1.2)) ticks.push(edge);
  for (const hz of ticks) {
    add("line", { x1: x(hz), x2: x(hz), y1: T, y2: H - B, stroke: "#e3e7ee" });
    // Low enough that the leftmost clears the lowest dB label, which ends at the corner.
    add("text", { x: x(hz), y: H - B + 19, "font-size": 11, "text-anchor": "middle", fill: "#5e6b7d" }, Math.round(hz));
  }
  add("text", { x: (L + W - R) / 2, y: H - 6, "font-size": 12, "text-anchor": "middle", fill: "#5e6b7d" }, "frequency (Hz)");
  add("text", { x: 14, y: (T + H - B) / 2, "font-size": 12, "text-anchor": "middle", fill: "#5e6b7d", transform: `rotate(-90 14 ${(T + H - B) / 2})` }, "strike spectrum (dB re full scale)");
  for (const c of curves) {
    add("polyline", {
      points: c.values.map((d, i) => (Number.isFinite(d) ? `${x(f[i]).toFixed(1)},${y(d).toFixed(1)}` : null)).filter(Boolean).join(" "),
      fill: "none", stroke: c.color, "stroke-width": c.width,
    });
  }
  return svg;
}

// --- fitting ---------------------------------------------------------------------------

const uploaded = [];

async function upload(files) {
  for (const file of files) {
    const li = el("li", { textContent: `${file.name}: uploading…` });
    $("#uploads").append(li);
    try {
      const r = await api("POST", `/api/uploads?name=${encodeURIComponent(file.name)}`, undefined, file);
      uploaded.push(r.id);
      li.textContent = `${r.name}: ${(r.bytes / 1024).toFixed(0)} kB`;
    } catch (e) {
      li.textContent = `${file.name}: ${e.message}`;
      li.className = "bad";
    }
  }
  $("#fit-button").disabled = uploaded.length === 0;
}

const drop = $("#drop");
drop.addEventListener("dragover", (e) => { e.preventDefault(); drop.classList.add("over"); });
drop.addEventListener("dragleave", () => drop.classList.remove("over"));
drop.addEventListener("drop", (e) => { e.preventDefault(); drop.classList.remove("over"); upload([...e.dataTransfer.files]); });
$("#files").addEventListener("change", (e) => upload([...e.target.files]));

$("#fit-form").addEventListener("submit", async (e) => {
  e.preventDefault();
  const name = $("#fit-name").value.trim();
  $("#fit-button").disabled = true;
  $("#fit-result").replaceChildren();
  try {
    const job = await api("POST", "/api/fit", { name, uploads: uploaded.slice() });
    await follow(job.id);
  } catch (err) {
    $("#fit-progress").textContent = "";
    $("#fit-result").replaceChildren(el("p", { className: "bad", textContent: `fit failed: ${err.message}` }));
  } finally {
    $("#fit-button").disabled = uploaded.length === 0;
  }
});

async function follow(id) {
  for (;;) {
    const j = await api("GET", `/api/fit/${id}`);
    $("#fit-progress").textContent = j.progress;
    if (j.state === "failed") throw new Error(j.error);
    if (j.state === "done") {
      uploaded.length = 0;
      $("#uploads").replaceChildren();
      const m = j.material;
      const loo = m.leave_one_out ? `, leave-one-out LSD ${m.leave_one_out.mean_lsd_db.toFixed(2)} dB` : " (one recording: no leave-one-out check)";
      $("#fit-result").replaceChildren(
        el("p", { textContent: `${m.name}: order ${m.order}, NRMSE ${m.nrmse.toFixed(4)}, LSD ${m.lsd_db.toFixed(2)} dB, ${m.strikes} strikes${loo}. ${j.saved}. Playable now: pick it in a channel's material list.` }),
        responsePlot(m));
      await loadLibrary();
      return;
    }
    await new Promise((r) => setTimeout(r, 300));
  }
}

connect();
