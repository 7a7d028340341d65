// sashil panel: the page. Binary batches of decimated stream rows arrive on the websocket; the
// plots redraw from them at the screen's frame rate (at most FPS_MAX), never per sample.
"use strict";
(function () {
  const TOKEN = document.querySelector('meta[name="sashil-token"]').content;
  // the order of a batch's columns (sashil.panel.frames.PLOT_COLUMNS)
  const COLUMNS = ["time_s", "theta_rad", "theta_dot_rad_s", "torque_cmd_nm", "torque_hat_nm",
    "band_lo_nm", "band_hi_nm", "current_cmd_a", "current_a", "theta_road_rad"];
  const WINDOW_S = 10;
  const FPS_MAX = 30;
  const $ = (id) => document.getElementById(id);

  const state = {
    client: null, controller: null, status: {}, laws: [], runId: 0,
    data: Object.fromEntries(COLUMNS.map((c) => [c, []])),
    frozen: null, dirty: false, batches: 0, bytes: 0, markers: [], redraws: 0,
  };
  window.panel = state; // read by the browser tests

  // -- requests ---------------------------------------------------------------------------------
  async function post(path, body) {
    const response = await fetch(path, {
      method: "POST",
      headers: { "Content-Type": "application/json", "X-Sashil-Token": TOKEN, "X-Sashil-Client": state.client || "" },
      body: JSON.stringify(body || {}),
    });
    const type = response.headers.get("content-type") || "";
    const data = type.includes("json") ? await response.json() : await response.text();
    if (!response.ok) throw new Error((data && data.error) || data || response.statusText);
    return data;
  }

  // -- STOP: the button, the space bar and Esc, on every page -------------------------------------
  let socket = null;
  function stop() {
    if (socket && socket.readyState === WebSocket.OPEN) socket.send(JSON.stringify({ stop: true }));
    post("/api/stop").catch(() => {}); // both: the socket is fastest, the request is there if it is down
  }
  $("stop").addEventListener("click", stop);
  const isStopKey = (e) => e.code === "Space" || e.key === " " || e.key === "Escape";
  window.addEventListener("keydown", (e) => { if (isStopKey(e)) { e.preventDefault(); e.stopPropagation(); if (!e.repeat) stop(); } }, true);
  window.addEventListener("keyup", (e) => { if (isStopKey(e)) { e.preventDefault(); e.stopPropagation(); } }, true);
  window.addEventListener("keypress", (e) => { if (isStopKey(e)) { e.preventDefault(); e.stopPropagation(); } }, true);

  // -- laws and their parameters --------------------------------------------------------------
  function lawOf(name) { return state.laws.find((l) => l.name === name); }
  function drawParams() {
    const law = lawOf($("law").value);
    $("law-doc").textContent = law ? law.doc : "";
    const table = $("params");
    table.innerHTML = "";
    for (const p of (law ? law.parameters : [])) {
      const row = table.insertRow();
      const name = row.insertCell();
      name.textContent = p.name + (p.unit ? ` [${p.unit}]` : "");
      if (p.required) name.innerHTML += ' <span class="req" title="required">*</span>';
      name.title = `${p.doc} (${p.accepts})`;
      const input = document.createElement("input");
      input.dataset.param = p.name;
      input.placeholder = p.required ? "required" : JSON.stringify(p.default);
      input.title = p.accepts;
      row.insertCell().appendChild(input);
    }
  }
  async function loadLaws() {
    const response = await fetch("/api/laws", { headers: { "X-Sashil-Token": TOKEN } });
    state.laws = await response.json();
    const select = $("law");
    for (const law of state.laws) {
      const option = document.createElement("option");
      option.value = option.textContent = law.name;
      select.appendChild(option);
    }
    select.value = lawOf("skyhook") ? "skyhook" : state.laws[0].name;
    drawParams();
  }
  $("law").addEventListener("change", drawParams);

  // -- start -------------------------------------------------------------------------------------
  $("start").addEventListener("click", async () => {
    $("refusal").textContent = "";
    const params = {};
    for (const input of $("params").querySelectorAll("input")) params[input.dataset.param] = input.value;
    const duration = $("duration").value.trim();
    const choice = {
      law: $("law").value, params, road: $("road").value.trim() || null,
      duration_s: duration === "" ? null : Number(duration),
      driver: $("driver").value || null, port: $("port").value.trim() || null,
    };
    try { await post("/api/start", choice); } catch (err) { $("refusal").textContent = err.message; }
  });

  // -- doctor: the board checks, in a child process, on an idle rig ---------------------------------
  $("doctor").addEventListener("click", async () => {
    $("refusal").textContent = "";
    const table = $("doctor-table");
    table.innerHTML = "<tr><td>checking ...</td></tr>";
    try {
      const answer = await post("/api/doctor", { driver: $("driver").value || null, port: $("port").value.trim() || null });
      table.innerHTML = "";
      for (const check of answer.checks) {
        const row = table.insertRow();
        row.className = check.status;
        for (const text of [check.status, `${check.group}/${check.name}`, check.found + (check.fix ? ` -> ${check.fix}` : "")]) cell(row, text);
      }
      state.doctor = answer;
    } catch (err) { table.innerHTML = ""; $("refusal").textContent = err.message; }
  });

  // -- live tuning: sliders send on release, number inputs on Enter --------------------------------
  function drawSliders(status) {
    const box = $("sliders");
    box.innerHTML = "";
    const law = lawOf(status.law);
    if (!law) return;
    for (const p of law.parameters) {
      if (!String(p.kind).startsWith("float")) continue;
      const value = status.values[p.name];
      if (typeof value !== "number") continue;
      const low = p.low ?? 0;
      const high = p.high ?? Math.max(4 * Math.abs(value), low + 1);
      const div = document.createElement("div");
      div.className = "slider";
      div.innerHTML = `<div>${p.name}${p.unit ? ` [${p.unit}]` : ""}</div>`;
      const range = Object.assign(document.createElement("input"), { type: "range", min: low, max: high, step: (high - low) / 200, value });
      const number = Object.assign(document.createElement("input"), { type: "number", step: "any", value });
      range.dataset.param = number.dataset.param = p.name;
      range.addEventListener("input", () => { number.value = range.value; }); // shown while dragging, not sent
      range.addEventListener("change", () => tune(p.name, Number(range.value))); // the release
      number.addEventListener("keydown", (e) => { if (e.key === "Enter") tune(p.name, number.value === "" ? NaN : Number(number.value)); });
      div.append(range, " ", number);
      box.appendChild(div);
    }
  }
  async function tune(name, value) {
    $("tune-refusal").textContent = "";
    const ramp = $("ramp").value.trim();
    try {
      await post("/api/tune", { set: { [name]: Number.isFinite(value) ? value : String(value) }, ramp_s: ramp === "" ? null : Number(ramp) });
    } catch (err) {
      $("tune-refusal").textContent = err.message;
      drawSliders(state.status); // the law kept its values: so do the sliders
    }
  }
  $("restore").addEventListener("click", async () => {
    $("tune-refusal").textContent = "";
    try { await post("/api/restore"); } catch (err) { $("tune-refusal").textContent = err.message; }
  });
  $("save").addEventListener("click", async () => {
    $("tune-refusal").textContent = "";
    try { download(`${state.status.law || "panel"}-tuned.yaml`, await post("/api/save"), "application/x-yaml"); }
    catch (err) { $("tune-refusal").textContent = err.message; }
  });
  $("hand-over").addEventListener("click", () => post("/api/hand-over").catch(() => {}));

  function download(name, text, type) {
    const link = document.createElement("a");
    link.href = URL.createObjectURL(new Blob([text], { type }));
    link.download = name;
    link.click();
    setTimeout(() => URL.revokeObjectURL(link.href), 1000);
  }

  // -- plots -------------------------------------------------------------------------------------
  const markerPlugin = {
    hooks: {
      draw: [(u) => {
        const ctx = u.ctx;
        ctx.save();
        ctx.strokeStyle = "#8e24aa";
        ctx.setLineDash([4, 3]);
        for (const m of state.markers) {
          const x = u.valToPos(m.time_s, "x", true);
          if (x < u.bbox.left || x > u.bbox.left + u.bbox.width) continue;
          ctx.beginPath(); ctx.moveTo(x, u.bbox.top); ctx.lineTo(x, u.bbox.top + u.bbox.height); ctx.stroke();
        }
        ctx.restore();
      }],
    },
  };
  const PLOTS = [ // time_s on every x axis
    { title: "arm angle θ [rad]", series: [["theta_rad", "θ", "#1565c0"]] },
    { title: "arm rate θ̇ [rad/s]", series: [["theta_dot_rad_s", "θ̇", "#1565c0"]] },
    { title: "torque [N m]: T* against T̂, feasible band", series: [["band_lo_nm", "band T(0)", "#bbb"], ["band_hi_nm", "band T(i_max)", "#bbb"], ["torque_cmd_nm", "T*", "#c62828"], ["torque_hat_nm", "T̂", "#1565c0"]], band: true },
    { title: "current [A]: commanded against measured", series: [["current_cmd_a", "i*", "#c62828"], ["current_a", "i", "#1565c0"]] },
    { title: "road θ_road [rad]", series: [["theta_road_rad", "road", "#2e7d32"]] },
  ];
  const sync = uPlot.sync("sashil");
  const charts = PLOTS.map((plot) => {
    const opts = {
      title: plot.title, width: 600, height: 170,
      cursor: { sync: { key: sync.key } },
      scales: { x: { time: false } },
      axes: [{ size: 30 }, { size: 70, values: (u, vals) => vals.map((v) => +v.toPrecision(3)) }],
      series: [{ label: "t [s]" }, ...plot.series.map(([, label, stroke]) => ({ label, stroke, width: 1.5 }))],
      plugins: [markerPlugin],
    };
    if (plot.band) opts.bands = [{ series: [2, 1], fill: "rgba(120,120,120,0.15)" }];
    const chart = new uPlot(opts, [[], ...plot.series.map(() => [])], $("plots"));
    chart.columns = plot.series.map(([c]) => c);
    return chart;
  });
  state.charts = charts;
  function resize() {
    const width = Math.max(300, $("plots").clientWidth - 4);
    for (const chart of charts) chart.setSize({ width, height: 170 });
  }
  window.addEventListener("resize", resize);
  resize();

  function clearData() {
    for (const c of COLUMNS) state.data[c] = [];
    state.markers = [];
    state.dirty = true;
  }
  function addBatch(buffer) {
    const view = new DataView(buffer);
    const n = view.getUint32(0, true);
    const width = view.getUint32(4, true);
    const values = new Float64Array(buffer.slice(8));
    for (let j = 0; j < width && j < COLUMNS.length; j++) {
      const column = state.data[COLUMNS[j]];
      for (let i = 0; i < n; i++) {
        const v = values[j * n + i];
        column.push(Number.isNaN(v) ? null : v);
      }
    }
    const time = state.data.time_s;
    const newest = time.length ? time[time.length - 1] : 0;
    let cut = 0;
    while (cut < time.length && time[cut] < newest - WINDOW_S) cut++;
    if (cut > 0) for (const c of COLUMNS) state.data[c].splice(0, cut);
    state.batches += 1;
    state.bytes += buffer.byteLength;
    state.dirty = true;
  }
  function shown() { return state.frozen || state.data; }
  let lastDraw = 0;
  function draw(now) {
    requestAnimationFrame(draw);
    if (!state.dirty || state.frozen || now - lastDraw < 1000 / FPS_MAX - 2) return;
    lastDraw = now;
    state.dirty = false;
    const data = state.data;
    for (const chart of charts) chart.setData([data.time_s, ...chart.columns.map((c) => data[c])]);
    state.redraws += 1;
  }
  requestAnimationFrame(draw);
  setInterval(() => { $("fps").textContent = `${state.redraws} redraws/s, ${state.batches} batches`; state.redraws = 0; }, 1000);

  $("pause").addEventListener("change", () => {
    state.frozen = $("pause").checked ? Object.fromEntries(COLUMNS.map((c) => [c, state.data[c].slice()])) : null;
    state.dirty = true;
  });
  $("csv").addEventListener("click", () => {
    const data = shown();
    const x = charts[0].scales.x;
    const lines = [COLUMNS.join(",")];
    for (let i = 0; i < data.time_s.length; i++) {
      const t = data.time_s[i];
      if (x.min != null && (t < x.min || t > x.max)) continue;
      lines.push(COLUMNS.map((c) => (data[c][i] == null ? "" : data[c][i])).join(","));
    }
    download("panel-visible.csv", lines.join("\n") + "\n", "text/csv");
  });

  // -- runs: the folders under the runs folder, their files, several overlaid ----------------------
  const OVERLAY_COLORS = ["#1565c0", "#c62828", "#2e7d32", "#ef6c00", "#6a1b9a", "#00838f", "#5d4037"];
  function cell(row, text) { const td = row.insertCell(); td.textContent = text == null ? "" : String(text); return td; }
  async function loadRuns() {
    const response = await fetch("/api/runs", { headers: { "X-Sashil-Token": TOKEN } });
    const runs = await response.json();
    state.runs = runs;
    const body = $("run-table").tBodies[0];
    body.innerHTML = "";
    for (const run of runs) {
      const row = body.insertRow();
      const box = Object.assign(document.createElement("input"), { type: "checkbox", disabled: !run.data });
      box.dataset.run = run.name;
      row.insertCell().appendChild(box);
      cell(row, run.name); cell(row, run.verb); cell(row, run.law.split(":").pop()); cell(row, run.road);
      cell(row, run.exit_status); cell(row, (run.started_utc || "").slice(0, 19)); cell(row, run.cycles); cell(row, run.missed_deadlines);
      const files = row.insertCell();
      for (const file of run.files) {
        const link = Object.assign(document.createElement("a"), { href: "#", textContent: file });
        link.addEventListener("click", (e) => { e.preventDefault(); openFile(run.name, file); });
        files.appendChild(link);
      }
    }
  }
  async function openFile(name, file) {
    const view = $("run-view");
    const url = `/api/runs/${encodeURIComponent(name)}/${encodeURIComponent(file)}`;
    view.innerHTML = `<h3>${name}/${file}</h3>`;
    if (file.endsWith(".png")) { view.appendChild(Object.assign(document.createElement("img"), { src: url, alt: file })); return; }
    const text = await (await fetch(url, { headers: { "X-Sashil-Token": TOKEN } })).text();
    view.appendChild(Object.assign(document.createElement("pre"), { textContent: text }));
  }
  let overlayChart = null;
  async function overlay() {
    const names = [...$("run-table").querySelectorAll("input:checked")].map((box) => box.dataset.run);
    const signal = $("overlay-signal").value;
    $("overlay-note").textContent = names.length ? "" : "select one run or more";
    if (!names.length) return;
    const tables = [];
    for (const name of names) {
      const response = await fetch(`/api/runs/${encodeURIComponent(name)}/traces`, { headers: { "X-Sashil-Token": TOKEN } });
      if (!response.ok) continue;
      const buffer = await response.arrayBuffer();
      const view = new DataView(buffer);
      const n = view.getUint32(0, true);
      const values = new Float64Array(buffer.slice(8));
      const column = (c) => Array.from(values.subarray(COLUMNS.indexOf(c) * n, (COLUMNS.indexOf(c) + 1) * n), (v) => (Number.isNaN(v) ? null : v));
      tables.push([column("time_s"), column(signal)]);
    }
    if (overlayChart) overlayChart.destroy();
    const data = uPlot.join(tables);
    overlayChart = new uPlot({
      title: `${$("overlay-signal").selectedOptions[0].textContent} against time_s, runs overlaid`,
      width: Math.max(300, $("runs").clientWidth - 24), height: 220, scales: { x: { time: false } },
      axes: [{ size: 30 }, { size: 70, values: (u, vals) => vals.map((v) => +v.toPrecision(3)) }],
      series: [{ label: "t [s]" }, ...names.map((name, i) => ({ label: name, stroke: OVERLAY_COLORS[i % OVERLAY_COLORS.length], width: 1.5, spanGaps: true }))],
    }, data, $("overlay-plot"));
    state.overlay = { names, data };
  }
  $("report").addEventListener("click", async () => {
    const names = [...$("run-table").querySelectorAll("input:checked")].map((box) => box.dataset.run);
    const view = $("run-view");
    view.innerHTML = "<h3>sashil report: running ...</h3>";
    try {
      const text = await post("/api/report", { runs: names });
      view.innerHTML = `<h3>sashil report ${names.join(" ")}</h3>`;
      view.appendChild(Object.assign(document.createElement("pre"), { textContent: text }));
      state.report = text;
    } catch (err) { view.innerHTML = ""; $("overlay-note").textContent = err.message; }
  });
  $("refresh-runs").addEventListener("click", loadRuns);
  $("overlay").addEventListener("click", overlay);

  // -- status ------------------------------------------------------------------------------------
  function showStatus(status) {
    const previous = state.status;
    state.status = status;
    if (status.run_id !== state.runId) { state.runId = status.run_id; clearData(); }
    if (previous.state && previous.state !== "idle" && status.state === "idle") loadRuns(); // the run's folder is complete
    state.markers = status.markers || [];
    const badge = $("state");
    badge.textContent = status.state + (status.state === "idle" && status.exit_status ? ` (last run: ${status.exit_status})` : "");
    badge.className = `badge ${status.state}`;
    $("counts").textContent = status.run_id
      ? `${status.law}  cycles ${status.cycles}  missed ${status.missed_deadlines} (${(100 * status.missed_share).toFixed(2)} %)  ${status.folder}`
      : "";
    if (previous.run_id !== status.run_id || previous.state !== status.state
        || JSON.stringify(previous.values) !== JSON.stringify(status.values)) drawSliders(status);
    applyRole();
  }
  function applyRole() {
    const controls = state.client !== null && state.client === state.controller;
    const running = state.status.state && state.status.state !== "idle";
    $("role").textContent = controls ? "you control" : "watching (STOP works)";
    $("hand-over").hidden = !controls;
    for (const el of document.querySelectorAll("#bench input, #bench select, #bench button")) el.disabled = !controls || running;
    for (const el of document.querySelectorAll("#tuning input, #tuning #restore")) el.disabled = !controls || !running;
  }
  function showEvents(events) {
    const list = $("events");
    for (const e of events) {
      const item = document.createElement("li");
      item.className = e.kind;
      item.textContent = e.text;
      list.appendChild(item);
    }
    while (list.children.length > 200) list.removeChild(list.firstChild);
    list.scrollTop = list.scrollHeight;
  }

  // -- the websocket: the token is a subprotocol (a browser cannot set headers on one) -------------
  function connect() {
    const url = `${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws`;
    socket = new WebSocket(url, ["sashil-panel.v1", `token.${TOKEN}`]);
    socket.binaryType = "arraybuffer";
    socket.onmessage = (msg) => {
      if (msg.data instanceof ArrayBuffer) { addBatch(msg.data); return; }
      const m = JSON.parse(msg.data);
      if (m.type === "hello") { state.client = m.client; showStatus(m); }
      else if (m.type === "status") showStatus(m);
      else if (m.type === "events") showEvents(m.events);
      else if (m.type === "control") { state.controller = m.controller; applyRole(); }
    };
    socket.onclose = () => {
      $("state").textContent = "disconnected: reconnecting";
      state.client = null;
      applyRole();
      setTimeout(connect, 1000);
    };
  }
  loadLaws().then(connect).then(loadRuns);
})();
