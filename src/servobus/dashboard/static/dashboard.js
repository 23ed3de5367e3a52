// The servobus dashboard page: takes the server's updates (server-sent events, one JSON object per
// update), keeps a window of each motor's fields, and draws tables and uPlot charts from them.
"use strict";

const MAX_WINDOW_S = 120;
// The tables and the plots are redrawn at most this often (the updates are kept at every one):
// drawing them at every update (30 a second) took headless Chromium a whole core, and on the control
// loop's own machine that core is the loop's (bench/RESULTS.md, the dashboard section)
const TABLES_MS = 250;
const PLOTS_MS = 100;
const COLORS = ["#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2",
                "#17becf", "#bcbd22", "#7f7f7f"];

const state = {
  commands: false,
  paused: false,
  lastAt: 0,              // when the last update came (Date.now())
  tablesAt: -Infinity,    // when the tables were last redrawn (performance.now())
  plotsAt: -Infinity,     // when the plots were
  framesNew: false,       // frames came since the frame table was drawn
  times: [],              // update times (s since the dashboard started)
  series: new Map(),      // "motorKey|field" or "motorKey|set.field" -> values aligned with times
  busSeries: new Map(),   // "bus|load" ... -> values
  fields: new Set(),
  motorKeys: [],
  last: null,
  frames: {},             // bus -> its frame view rows, as last sent
  plots: {},
  plotShape: {},
};

const $ = (sel) => document.querySelector(sel);

function el(tag, attrs, text) {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) node.setAttribute(k, v);
  if (text !== undefined && text !== null) node.textContent = text;
  return node;
}

function fmt(value, digits = 2) {
  if (value === null || value === undefined) return "–";
  if (typeof value === "number") return Number.isInteger(value) ? String(value) : value.toFixed(digits);
  return String(value);
}

function ms(seconds) {
  return seconds === null || seconds === undefined ? "–" : (seconds * 1000).toFixed(2) + " ms";
}

function say(text, bad) {
  const box = $("#message");
  box.textContent = text;
  box.className = bad ? "bad" : "good";
}

// ---- history ----

function push(map, key, value, length) {
  let values = map.get(key);
  if (!values) {
    values = new Array(length - 1).fill(null);
    map.set(key, values);
  }
  values.push(value === undefined ? null : value);
}

function record(update) {
  state.times.push(update.t);
  const n = state.times.length;
  for (const m of update.motors) {
    for (const [name, value] of Object.entries(m.fields)) {
      state.fields.add(name);
      push(state.series, m.key + "|" + name, value, n);
    }
    if (m.setpoint) {
      for (const [name, value] of Object.entries(m.setpoint.fields)) {
        push(state.series, m.key + "|set." + name, value, n);
      }
    }
  }
  for (const b of update.buses) {
    push(state.busSeries, b.name + "|load", b.bus_load_pct, n);
    push(state.busSeries, b.name + "|rate", b.request_rate_hz, n);
  }
  update.loops.forEach((l, i) => {
    push(state.busSeries, "loop" + i + "|late", l.late_p99_s === null ? null : l.late_p99_s * 1000, n);
    push(state.busSeries, "loop" + i + "|age", l.state_age_p99_s === null ? null : l.state_age_p99_s * 1000, n);
  });
  for (const values of [...state.series.values(), ...state.busSeries.values()]) {
    if (values.length < n) values.push(null);  // a series with no value this update
  }
  const oldest = update.t - MAX_WINDOW_S;
  let drop = 0;
  while (drop < state.times.length && state.times[drop] < oldest) drop++;
  if (drop > 0) {
    state.times.splice(0, drop);
    for (const values of [...state.series.values(), ...state.busSeries.values()]) values.splice(0, drop);
  }
}

// ---- tables ----

function renderMotors(update) {
  const body = $("#motors tbody");
  const keys = update.motors.map((m) => m.key);
  if (keys.join() !== state.motorKeys.join()) {
    state.motorKeys = keys;
    body.replaceChildren();
    for (const m of update.motors) {
      const row = el("tr", { "data-key": m.key });
      for (const col of ["bus", "id", "family", "status", "fault", "temperature", "reply", "age", "fields", "setpoint"]) {
        row.append(el("td", { "data-col": col }));
      }
      const act = el("td", { "data-col": "actions" });
      for (const kind of ["stop", "off"]) {
        const button = el("button", { class: kind, "data-key": m.key, "data-kind": kind }, kind);
        button.addEventListener("click", () => command([m.key], kind));
        act.append(button);
      }
      row.append(act);
      body.append(row);
    }
    renderMotorChoice(update);
    applyMode();
  }
  for (const m of update.motors) {
    const row = body.querySelector(`tr[data-key="${CSS.escape(m.key)}"]`);
    const cell = (col) => row.querySelector(`td[data-col="${col}"]`);
    cell("bus").textContent = m.bus;
    cell("id").textContent = m.id;
    cell("family").textContent = m.family;
    cell("status").textContent = m.status;
    cell("status").title = m.reason || "";
    row.className = "status-" + m.status + (m.fault.length ? " faulted" : "");
    cell("fault").textContent = m.fault.length ? m.fault.join(", ") : "none";
    cell("temperature").textContent = fmt(m.temperature_c, 0);
    cell("reply").textContent = m.reply || "–";
    cell("age").textContent = m.age_s === null ? "–" : m.age_s.toFixed(2) + " s";
    // (a no-break space in each "name value": a narrow cell wraps between fields, not inside one)
    cell("fields").textContent = Object.entries(m.fields)
      .filter(([name]) => name !== "temperature_c")
      .map(([name, value]) => `${name}\u00a0${fmt(value)}`).join("  ");
    cell("setpoint").textContent = m.setpoint
      ? m.setpoint.name + " " + Object.entries(m.setpoint.fields).map(([k, v]) => `${k}\u00a0${fmt(v)}`).join(" ")
      : "–";
  }
  const online = update.motors.filter((m) => m.status === "online").length;
  $("#summary").textContent = `${update.motors.length} motors, ${online} online · t ${update.t.toFixed(1)} s`;
}

function renderMotorChoice(update) {
  const choice = $("#plot-motors");
  const chosen = new Set([...choice.selectedOptions].map((o) => o.value));
  choice.replaceChildren();
  update.motors.forEach((m, i) => {
    const option = el("option", { value: m.key }, m.key + " (" + m.family + ")");
    option.selected = chosen.size ? chosen.has(m.key) : i < 4;
    choice.append(option);
  });
}

function renderFieldChoice() {
  const select = $("#field");
  const have = new Set([...select.options].map((o) => o.value));
  const fields = [...state.fields].sort();
  if (fields.every((f) => have.has(f)) && have.size === fields.length) return;
  const current = select.value;
  select.replaceChildren(...fields.map((f) => el("option", { value: f }, f)));
  const preferred = ["speed_dps", "angle_deg", "position_rad", "current_a"].find((f) => state.fields.has(f));
  select.value = have.has(current) ? current : (preferred || fields[0] || "");
}

function renderBuses(update) {
  const body = $("#buses tbody");
  body.replaceChildren(...update.buses.map((b) => {
    const row = el("tr", { "data-bus": b.name });
    for (const value of [b.name, fmt(b.bus_load_pct, 1), fmt(b.request_rate_hz, 0), b.requests, b.replies,
                         b.timeouts, b.late, b.ambiguous, b.duplicate, b.malformed, b.restarts]) {
      row.append(el("td", {}, fmt(value)));
    }
    row.append(el("td", {}, ms(b.latency_p99_s)));
    return row;
  }));
  const loops = $("#loops tbody");
  loops.replaceChildren(...update.loops.map((l, i) => {
    const row = el("tr", { "data-loop": String(i) });
    for (const value of [`${fmt(l.hz, 0)} Hz`, l.ticks, l.late_ticks, l.skipped, l.overruns, ms(l.late_p99_s),
                         ms(l.state_age_p50_s), ms(l.state_age_p99_s), l.lost, l.throttled, l.not_sent]) {
      row.append(el("td", {}, fmt(value)));
    }
    return row;
  }));
  $("#loops").style.display = update.loops.length ? "" : "none";
}

function renderFrames() {
  const wanted = $("#frame-filter").value.trim().toLowerCase();
  const rows = [];
  let total = 0;
  for (const [bus, frames] of Object.entries(state.frames)) {
    const b = { name: bus };
    for (const f of frames) {
      total++;
      const text = `${b.name} ${f.dir} ${f.id} ${f.data} ${f.name}`.toLowerCase();
      if (wanted && !wanted.split(/\s+/).every((w) => text.includes(w))) continue;
      const row = el("tr", { class: f.dir });
      for (const [col, value] of [["bus", b.name], ["dir", f.dir], ["id", f.id], ["data", f.data],
                                  ["count", f.count], ["rate", fmt(f.rate_hz, 0)], ["name", f.name]]) {
        row.append(el("td", { "data-col": col }, fmt(value)));
      }
      rows.push(row);
    }
  }
  $("#frames tbody").replaceChildren(...rows);
  $("#frame-count").textContent = total
    ? `${rows.length} of ${total} identifiers`
    : "no frames seen (a bus the dashboard did not open shows its decoded replies only)";
}

// ---- plots ----

function windowed(values) {
  const span = Number($("#window").value);
  const t = state.times;
  const from = t.length ? t[t.length - 1] - span : 0;
  let i = 0;
  while (i < t.length && t[i] < from) i++;
  return values.slice(i);
}

function drawPlot(id, title, lines, height) {
  const box = $("#" + id);
  const shape = lines.map((l) => l.label).join("\n");
  const data = [windowed(state.times), ...lines.map((l) => windowed(l.values))];
  let plot = state.plots[id];
  if (!plot || state.plotShape[id] !== shape || plot.width !== Math.floor(box.clientWidth)) {
    if (plot) plot.destroy();
    const series = [{ label: "t (s)" }, ...lines.map((l, i) => ({
      label: l.label,
      stroke: COLORS[l.color ?? i % COLORS.length],
      width: l.dash ? 1 : 1.5,
      dash: l.dash ? [6, 4] : undefined,
      spanGaps: true,
      points: { show: false },  // (uPlot dots a sparse line: a slow first second, a loaded host)
      scale: l.scale || "y",
    }))];
    // one axis per unit: the first on the left, the others on the right; a unit's scale (all
    // counts, rates and times here) from 0 (no zoom on jitter); "y" (a motor's field) as it comes
    const units = [...new Set(lines.map((l) => l.scale || "y"))];
    const axes = units.map((unit, i) => ({
      scale: unit, side: i ? 1 : 3, label: unit === "y" ? undefined : unit, grid: { show: i === 0 },
    }));
    const fromZero = { range: (u, min, max) => [0, Math.max(max, 1) * 1.1] };
    plot = new uPlot({
      title, width: Math.floor(box.clientWidth), height,
      scales: { x: { time: false }, ...Object.fromEntries(units.filter((k) => k !== "y").map((k) => [k, fromZero])) },
      axes: [{ label: "t (s)" }, ...(axes.length ? axes : [{}])],
      series,
    }, data, box);
    state.plots[id] = plot;
    state.plotShape[id] = shape;
  } else {
    plot.setData(data);
  }
}

function renderPlots() {
  renderFieldChoice();
  const field = $("#field").value;
  const chosen = [...$("#plot-motors").selectedOptions].map((o) => o.value);
  const lines = [];
  chosen.forEach((key, i) => {
    const measured = state.series.get(key + "|" + field);
    if (measured) lines.push({ label: `${key} ${field}`, values: measured, color: i % COLORS.length });
    const set = state.series.get(key + "|set." + field);
    if (set && $("#show-setpoints").checked) {
      lines.push({ label: `${key} set-point`, values: set, color: i % COLORS.length, dash: true });
    }
  });
  drawPlot("plot", field ? `${field} by motor` : "no field yet", lines, 300);
  const bus = [], loop = [];
  const kinds = {
    load: ["load %", "%"], rate: ["requests/s", "requests/s"],
    late: ["tick late p99", "ms"], age: ["state age p99", "ms"],
  };
  for (const [key, values] of state.busSeries) {
    const [name, what] = key.split("|");
    const [label, unit] = kinds[what];
    (what === "load" || what === "rate" ? bus : loop).push({ label: `${name} ${label}`, values, scale: unit });
  }
  drawPlot("plot-bus", "bus load and request rate", bus, 180);
  drawPlot("plot-loop", "loop: tick lateness and state age", loop, 180);
}

// ---- commands ----

function applyMode() {
  $("#mode").textContent = state.commands ? "commands allowed" : "read-only";
  $("#mode").className = "badge " + (state.commands ? "armed" : "");
  const why = state.commands ? "" : "read-only: start the dashboard with --allow-commands";
  for (const button of document.querySelectorAll("button.stop, button.off, #stop-all, #off-all")) {
    button.disabled = !state.commands;
    button.title = why || button.dataset.kind || button.textContent;
  }
}

async function command(motors, kind) {
  try {
    const answer = await fetch("api/stop", {
      method: "POST",
      headers: { "content-type": "application/json" },
      body: JSON.stringify({ motors, kind }),
    });
    const body = await answer.json();
    if (!answer.ok) {
      say(`${kind} refused: ${body.error}`, true);
      return;
    }
    const missing = body.not_acknowledged.length ? `; not acknowledged: ${body.not_acknowledged.join(", ")}` : "";
    say(`${kind}: acknowledged by ${body.acknowledged.join(", ") || "none"}${missing}`, missing !== "");
  } catch (error) {
    say(`${kind} failed: ${error}`, true);
  }
}

// ---- the stream ----

function take(update) {
  if (state.last && update.t < state.last.t) reset();  // the server restarted: a new run
  state.last = update;
  state.lastAt = Date.now();
  record(update);
  // a bus's frames come in some updates only (the server makes them a few times a second)
  for (const b of update.buses.filter((b) => b.frames)) {
    state.frames[b.name] = b.frames;
    state.framesNew = true;
  }
  const now = performance.now();
  if (now - state.tablesAt >= TABLES_MS || update.motors.length !== state.motorKeys.length) {
    state.tablesAt = now;
    renderMotors(update);
    renderBuses(update);
    if (state.framesNew) {
      state.framesNew = false;
      renderFrames();
    }
  }
  if (!state.paused && now - state.plotsAt >= PLOTS_MS) {  // (Pause holds the plots; the tables go on)
    state.plotsAt = now;
    renderPlots();
  }
}

function reset() {
  state.times = [];
  state.series = new Map();
  state.busSeries = new Map();
  state.frames = {};
  state.motorKeys = [];
}

async function fetchInfo() {
  try {
    const info = await (await fetch("api/info")).json();
    state.commands = info.commands;
    $("#version").textContent = info.version;
  } catch (error) {
    say(`no answer from the dashboard: ${error}`, true);
  }
  applyMode();
}

function showConnection(text, live) {
  $("#conn").textContent = text;
  $("#conn").className = "badge " + (live ? "on" : "off");
}

async function start() {
  await fetchInfo();
  $("#stop-all").addEventListener("click", () => command("all", "stop"));
  $("#off-all").addEventListener("click", () => command("all", "off"));
  $("#pause").addEventListener("click", () => {
    state.paused = !state.paused;
    $("#pause").textContent = state.paused ? "Resume" : "Pause";
  });
  for (const id of ["#field", "#plot-motors", "#window", "#show-setpoints"]) {
    $(id).addEventListener("change", () => renderPlots());
  }
  $("#frame-filter").addEventListener("input", () => renderFrames());
  window.addEventListener("resize", () => state.last && renderPlots());
  const events = new EventSource("api/events");
  events.addEventListener("open", () => fetchInfo());  // (again after a reconnect: a new server)
  events.addEventListener("update", (event) => {
    showConnection("live", true);
    take(JSON.parse(event.data));
  });
  events.onerror = () => showConnection("disconnected", false);
  setInterval(() => {  // updates that stop coming without an error: say so
    if (state.lastAt && Date.now() - state.lastAt > 2000 && events.readyState === EventSource.OPEN) {
      showConnection("stale", false);
    }
  }, 1000);
}

start();
