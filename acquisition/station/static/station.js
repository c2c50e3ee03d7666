// impactlab station page: renders the server-held session state; actions go back as JSON POSTs.
"use strict";
(function () {
  const token = new URLSearchParams(location.search).get("token") || "";
  let client = sessionStorage.getItem("station-client");
  if (!client) {
    client = Math.random().toString(36).slice(2) + Date.now().toString(36);
    sessionStorage.setItem("station-client", client);
  }
  const $ = (sel) => document.querySelector(sel);
  const plotEl = (name) => document.querySelector(`[data-plot="${name}"]`);
  const cfg = { displayModeBar: false, responsive: true };
  const seen = { hit: 0, frf: 0, setup: 0, current: -1, planKey: "" };
  let state = null;
  let geometry = null;
  let inControl = false;
  if (typeof window.Plotly === "undefined") {  // plotly not installed: the page works, without plots
    window.Plotly = { react: () => Promise.resolve() };
    setTimeout(() => note("plots unavailable: install plotly on the station computer (pip install -e '.[station]')", "ERROR"), 0);
  }
  // for tests and the latency benchmark: hit sequence -> Date.now() when its plots were drawn
  window.stationStats = { shown: {}, errors: 0 };

  function api(path, body) {
    const opts = { headers: { "X-Station-Token": token } };
    if (body !== undefined) {
      opts.method = "POST";
      opts.headers["Content-Type"] = "application/json";
      opts.body = JSON.stringify(Object.assign({ client: client }, body));
    }
    return fetch(path, opts).then(async (r) => {
      const data = await r.json().catch(() => ({}));
      if (!r.ok) { const e = new Error(data.error || r.statusText); e.status = r.status; throw e; }
      return data;
    });
  }

  function note(text, level) {
    const li = document.createElement("li");
    li.className = level || "INFO";
    li.textContent = text;
    $("#messages").prepend(li);
  }

  // -- control lease ------------------------------------------------------------------------------
  function lease(take) {  // 200 either way: {control: false} while another tab controls
    return api("/api/lease", { take: !!take }).then((r) => { inControl = !!r.control; render(); })
      .catch((e) => { inControl = false; note("control: " + e.message, "WARNING"); render(); });
  }
  setInterval(() => { if (inControl) lease(false); }, 5000);
  $("#take-control").addEventListener("click", () => lease(true));

  // -- actions ------------------------------------------------------------------------------------
  // Each action names the hit or point it acts on, as this page shows it: the server refuses (409) one
  // made on a page that is out of date (a double click) instead of acting on the next hit or point.
  // One action at a time: clicks and keys while one is on its way (or until the page shows its
  // outcome) are dropped.
  let sending = null;  // the state version an action was sent from, while it is on its way
  const NAMES_HIT = ["accept", "reject"];
  const NAMES_POINT = ["arm", "next-point", "undo", "remeasure"];
  function act(action, extra) {
    if (!state || !inControl || !(state.allowed || []).includes(action)) return;
    if (sending !== null) return;
    const body = Object.assign({ action: action }, extra || {});
    if (NAMES_HIT.includes(action)) {
      if (!state.verdict || state.verdict.number == null) return;
      body.hit = state.verdict.number;
    } else if (NAMES_POINT.includes(action) && body.point === undefined) {
      body.point = state.current || 0;
    }
    if (action === "undo") body.hits = state.point_hits || 0;  // the hits on screen: a late second click is refused
    sending = state.version;
    api("/api/action", body).then(() => { if (state && state.version === sending) state.allowed = []; })
      .catch((e) => {
        note(`${action} not done: ${e.message}`, "WARNING");
        if (e.status === 409) lease(false);
      })
      .finally(() => { sending = null; render(); });
  }
  document.querySelectorAll("button[data-action]").forEach((b) => b.addEventListener("click", () => act(b.dataset.action)));
  $("#auto").addEventListener("change", (ev) => act("auto", { on: ev.target.checked }));
  document.addEventListener("keydown", (ev) => {
    if (!state || ["INPUT", "SELECT", "TEXTAREA"].includes(document.activeElement.tagName)) return;
    if (ev.key === "Enter") {
      ev.preventDefault();
      const order = { decide: "accept", ready: "arm", setup: "arm", complete: "next-point" };
      if (order[state.phase]) act(order[state.phase]);
    } else if (ev.key === "Backspace") {
      ev.preventDefault();
      if (state.phase === "decide") act("reject");
    }
  });

  // -- rendering ----------------------------------------------------------------------------------
  function render() {
    if (!state) return;
    const s = state;
    document.body.dataset.phase = s.phase;
    $("#device").textContent = s.device || "";
    $("#recording").textContent = s.recording ? "recording " + s.recording : "";
    const phaseText = { armed: `armed: strike at ${s.current_point || "the point"}`, ready: "ready: arm for the next hit",
      decide: "accept or reject the hit", complete: "point complete: next point (or undo, again)", setup: "set-up: test hits, then arm to start",
      busy: "working: carrying out the last action" };
    $("#phase").textContent = (phaseText[s.phase] || s.phase) + (s.phase === "error" && s.error ? ": " + s.error : "");
    $("#paused").hidden = !s.paused;
    $("#current-point").textContent = s.current_point || (s.plan && s.plan[s.current] ? s.plan[s.current].point : "-");
    $("#point-of").textContent = s.plan ? `(${(s.current || 0) + 1} of ${s.plan.length})` : "";
    $("#accepted-count").textContent = String(s.point_hits || 0);
    $("#hits-target").textContent = ` / ${s.hits_per_point || "?"}`;
    $("#totals").textContent = `accepted ${s.total_accepted || 0}, rejected ${s.total_rejected || 0} in total` +
      (s.summary ? "; " + s.summary : "");
    $("#auto").checked = !!s.auto;
    const ctl = $("#control");
    const someoneElse = s.controller && s.controller !== client;
    ctl.textContent = inControl ? "in control" : (someoneElse ? "read-only: another tab controls" : "read-only");
    ctl.className = "badge " + (inControl ? "good" : "warn");
    $("#take-control").hidden = inControl;
    const allowed = new Set(s.allowed || []);
    document.querySelectorAll("button[data-action]").forEach((b) => {
      let ok = inControl && allowed.has(b.dataset.action);
      if ((b.dataset.action === "undo" || b.dataset.action === "remeasure") && !(s.point_hits > 0)) ok = false;
      if (b.dataset.action === "remeasure" && s.phase === "finished") ok = false;  // the plan rows' "again" buttons
      if (b.dataset.action === "pause" && s.paused) ok = false;
      if (b.dataset.action === "resume" && !s.paused) ok = false;
      b.disabled = !ok;
    });
    $("#auto").disabled = !(inControl && allowed.has("auto"));
    renderVerdict(s);
    renderPlan(s);
    renderMessages(s.messages || []);
    const blobs = s.blobs || {};
    if (blobs.hit && blobs.hit !== seen.hit) { seen.hit = blobs.hit; loadHit(); }
    if (blobs.frf && blobs.frf !== seen.frf) { seen.frf = blobs.frf; loadFrf(); }
    if (blobs.setup && blobs.setup !== seen.setup) { seen.setup = blobs.setup; loadSetup(); }
  }

  function renderVerdict(s) {
    const v = s.verdict;
    const el = $("#hit-verdict");
    const ul = $("#verdict-details");
    el.dataset.seq = String(s.hit_seq || 0);
    if (!v) { el.dataset.state = "none"; el.textContent = "no hit yet"; ul.innerHTML = ""; return; }
    el.dataset.state = v.state;
    const words = { accepted: "ACCEPTED", rejected: "REJECTED", decide: "accept or reject?", test: "TEST HIT" };
    el.textContent = (v.state === "test" || v.number == null ? "" : `hit ${v.number} at ${v.point}: `) + `${words[v.state] || v.state}` + (v.reasons.length ? " - " + v.reasons.join("; ") : "");
    const items = [
      `force peak ${v.force_peak_n} N, pulse ${v.pulse_width_ms} ms`,
      `double hit: ${v.double_hit ? "YES" : "no"} (second peak ${v.second_peak_pct} %)`,
      `overload: ${v.overload.some((o) => o) ? v.overload.map((o, i) => (o ? i + 1 : null)).filter((x) => x).join(", ") : "none"}`,
      `coherence so far: ${v.coherence === null ? "-" : v.coherence.toFixed(3)}`,
    ].concat(v.advice || []);
    ul.innerHTML = "";
    items.forEach((t) => { const li = document.createElement("li"); li.textContent = t; ul.appendChild(li); });
  }

  function renderPlan(s) {
    const rows = s.plan || [];
    const key = JSON.stringify([rows, s.current, s.point_hits, s.phase, inControl]);
    if (key === seen.planKey) return;
    seen.planKey = key;
    const tb = $("#plan tbody");
    tb.innerHTML = "";
    rows.forEach((r) => {
      const tr = document.createElement("tr");
      if (r.index === s.current && s.phase !== "setup") tr.className = "current";
      if (r.done) tr.classList.add("done");
      const n = r.index === s.current ? (s.point_hits || 0) : r.accepted;
      [r.index + 1, r.point, `${n} / ${s.hits_per_point}`, ""].forEach((t) => {
        const td = document.createElement("td"); td.textContent = t; tr.appendChild(td);
      });
      const canRedo = (r.done || r.index < s.current || s.phase === "finished") && r.index !== s.current
        || (s.phase === "finished" && r.index === s.current);
      if (canRedo && ["ready", "complete", "finished"].includes(s.phase)) {
        const b = document.createElement("button");
        b.type = "button"; b.textContent = "again"; b.dataset.redo = String(r.index);
        b.title = "measure this point again (its hits are withdrawn)";
        b.disabled = !inControl;
        b.addEventListener("click", () => act("remeasure", { point: r.index }));
        tr.children[3].appendChild(b);
      }
      tb.appendChild(tr);
    });
    drawGeometry();
  }

  function renderMessages(msgs) {
    const ol = $("#messages");
    const last = Number(ol.dataset.last || 0);
    msgs.filter((m) => m.id > last).forEach((m) => {
      const t = new Date(m.time * 1000).toLocaleTimeString();
      note(`${t} ${m.text}`, m.level);
      ol.dataset.last = String(m.id);
    });
    while (ol.children.length > 200) ol.removeChild(ol.lastChild);
  }

  // -- plots --------------------------------------------------------------------------------------
  const layoutBase = (title, x, y) => ({
    title: { text: title, font: { size: 13 }, x: 0.01, xanchor: "left", y: 0.98, yanchor: "top" }, margin: { l: 55, r: 12, t: 46, b: 42 },
    xaxis: { title: { text: x, standoff: 4 } }, yaxis: { title: { text: y } }, showlegend: true,
    legend: { orientation: "h", x: 1, xanchor: "right", y: 1.0, yanchor: "bottom", font: { size: 10 } }, uirevision: title,
  });
  const vline = (x, color, dash) => ({ type: "line", x0: x, x1: x, yref: "paper", y0: 0, y1: 1, line: { color: color, dash: dash || "dot", width: 1.5 } });
  const hline = (y, color) => ({ type: "line", y0: y, y1: y, xref: "paper", x0: 0, x1: 1, line: { color: color, dash: "dot", width: 1 } });

  function loadHit() {
    api("/api/blob/hit").then((h) => {
      const f = h.force;
      const shapes = [vline(h.trigger_ms, "#b3261e"), vline(h.pretrigger_ms, "#1c5fb8")];
      if (h.force_window_ms) shapes.push(vline(h.force_window_ms, "#777", "dash"));
      Plotly.react(plotEl("force"), [{ x: f.t_ms, y: f.y, name: f.name, line: { color: "#b3261e", width: 1.2 } }],
        Object.assign(layoutBase(`force (${f.unit}) at ${h.point}: trigger red, pre-trigger blue, window grey`, "time after trigger (ms)", f.unit),
          { shapes: shapes, xaxis: { title: { text: "time after trigger (ms)" }, range: [h.pretrigger_ms * 1.1, Math.max(30, (h.force_window_ms || 0) * 1.5)] } }), cfg);
      Plotly.react(plotEl("response"), h.responses.map((r) => ({ x: r.t_ms, y: r.y, name: r.name, line: { width: 1 } })),
        Object.assign(layoutBase("responses", "time after trigger (ms)", h.responses.length ? h.responses[0].unit : ""), { shapes: [vline(h.trigger_ms, "#b3261e"), vline(h.pretrigger_ms, "#1c5fb8")] }), cfg);
      const sp = h.spectrum;
      const sshapes = [hline(-10, "#c98a00"), hline(-20, "#b3261e")];
      if (sp.minus10_hz) sshapes.push(vline(sp.minus10_hz, "#c98a00"));
      if (sp.minus20_hz) sshapes.push(vline(sp.minus20_hz, "#b3261e"));
      const band = `band: -10 dB to ${sp.minus10_hz ? sp.minus10_hz.toFixed(0) : "?"} Hz, -20 dB to ${sp.minus20_hz ? sp.minus20_hz.toFixed(0) : "?"} Hz`;
      Plotly.react(plotEl("force-spectrum"), [{ x: sp.f_hz, y: sp.db, name: "force autospectrum", line: { color: "#b3261e", width: 1.2 } }],
        Object.assign(layoutBase("force spectrum (" + band + ")", "frequency (Hz)", "dB re max"), { shapes: sshapes, yaxis: { title: { text: "dB re max" }, range: [-60, 3] } }), cfg);
      window.stationStats.shown[h.seq] = Date.now();
    }).catch((e) => { window.stationStats.errors += 1; note("hit plots: " + e.message, "WARNING"); });
  }

  function loadFrf() {
    api("/api/blob/frf").then((d) => {
      const outs = d.outputs || [];
      const h1 = outs.map((o) => ({ x: d.f_hz, y: o.h1_db, name: "H1 " + o.name, line: { width: 1.2 } }));
      const h2 = outs.map((o) => ({ x: d.f_hz, y: o.h2_db, name: "H2 " + o.name, line: { width: 1, dash: "dot" }, visible: "legendonly" }));
      Plotly.react(plotEl("frf"), h1.concat(h2),
        layoutBase(`FRF at reference ${d.reference || "-"} (${d.n_averages} averages${state && state.phase === "decide" ? ", the hit on screen included" : ""})` + (d.levels ? "<br>linearity: " + d.levels.line : ""), "frequency (Hz)", `dB re 1 ${d.unit || ""}`), cfg);
      const ql = document.getElementById("quality-lines");
      if (ql) ql.replaceChildren(...(d.quality || []).map((t) => { const li = document.createElement("li"); li.textContent = t; return li; }));
      Plotly.react(plotEl("coherence"), outs.map((o) => ({ x: d.f_hz, y: o.coherence, name: o.name, line: { width: 1 } })),
        Object.assign(layoutBase("coherence", "frequency (Hz)", ""), { yaxis: { range: [0, 1.05] } }), cfg);
    }).catch((e) => note("FRF plots: " + e.message, "WARNING"));
  }

  function nodeOf(point) { const p = String(point).split(":"); return p[0] + ":" + p[1]; }

  function drawGeometry() {
    if (!geometry || !state) return;
    const el = plotEl("geometry");
    const nodes = geometry.nodes || {};
    const xs = [], ys = [], zs = [];
    (geometry.lines || []).forEach(([a, b]) => {
      if (!nodes[a] || !nodes[b]) return;
      xs.push(nodes[a][0], nodes[b][0], null); ys.push(nodes[a][1], nodes[b][1], null); zs.push(nodes[a][2], nodes[b][2], null);
    });
    const traces = [{ type: "scatter3d", mode: "lines", x: xs, y: ys, z: zs, name: "frame", line: { color: "#7d8b98", width: 4 }, hoverinfo: "skip" }];
    // the accelerometers first, as open squares: a point's dot drawn after stays visible inside one
    const groups = { sensor: [], done: [], todo: [], current: [] };
    (state.plan || []).forEach((r) => {
      const k = r.index === state.current && state.phase !== "finished" ? "current" : (r.done ? "done" : "todo");
      groups[k].push(r.point);
    });
    (state.outputs || []).forEach((p) => groups.sensor.push(p));
    const style = { done: ["#1f8a3b", 6], todo: ["#9aa7b3", 5], current: ["#e07b00", 11], sensor: ["#1c5fb8", 9] };
    const names = { done: "done", todo: "to do", current: "strike here", sensor: "accelerometers" };
    Object.keys(groups).forEach((k) => {
      const pts = groups[k].filter((p) => nodes[nodeOf(p)]);
      if (!pts.length) return;
      traces.push({ type: "scatter3d", mode: "markers", name: names[k], text: pts, hoverinfo: "text",
        x: pts.map((p) => nodes[nodeOf(p)][0]), y: pts.map((p) => nodes[nodeOf(p)][1]), z: pts.map((p) => nodes[nodeOf(p)][2]),
        marker: { color: style[k][0], size: style[k][1], symbol: k === "sensor" ? "square-open" : "circle" } });
    });
    Plotly.react(el, traces, { margin: { l: 0, r: 0, t: 0, b: 0 }, showlegend: true, legend: { orientation: "h", y: 0, font: { size: 10 } },
      uirevision: "geometry", scene: { aspectmode: "data", xaxis: { visible: false }, yaxis: { visible: false }, zaxis: { visible: false },
        camera: { eye: { x: 1.4, y: -1.6, z: 0.9 } } } }, cfg);
  }

  // -- set-up panel ---------------------------------------------------------------------------------
  let setupData = null;
  function loadSetup() {
    api("/api/blob/setup").then((d) => { setupData = d; drawSetup(); }).catch((e) => note("set-up: " + e.message, "WARNING"));
  }
  function drawSetup() {
    const d = setupData;
    const body = $("#setup-body");
    const dis = d.editable ? "" : " disabled";
    const ranges = d.capabilities.ranges_v;
    let html = "<table><tr><th>channel</th><th>point</th><th>mV/unit</th><th>range V</th></tr>";
    d.setup.channels.forEach((c, i) => {
      html += `<tr><td>${c.name} (${c.quantity})</td><td><input data-ch="${i}" data-key="point" value="${c.point}"${dis}></td>` +
        `<td><input data-ch="${i}" data-key="sensitivity" type="number" step="any" value="${c.sensitivity}"${dis}></td><td><select data-ch="${i}" data-key="range_v"${dis}>` +
        ranges.map((r) => `<option value="${r}"${Math.abs(r - c.range_v) < 1e-9 ? " selected" : ""}>${r}</option>`).join("") + "</select></td></tr>";
    });
    const t = d.setup.trigger;
    html += `</table><table><tr><td>trigger level</td><td><input id="trig-level" type="number" step="any" value="${t.level}"${dis}></td>` +
      `<td>pre-trigger (samples)</td><td><input id="trig-pre" type="number" min="0" max="${d.capabilities.max_pretrigger}" value="${t.pretrigger_samples}"${dis}></td></tr>` +
      `<tr><td>force window</td><td><input id="win-force" placeholder="20ms,5ms" value=""${dis}></td><td>exponential</td><td><input id="win-exp" placeholder="none" value=""${dis}></td></tr></table>` +
      `<p class="muted">${d.setup.sample_rate_hz} Hz, ${d.setup.block_size} samples; windows now: ${d.windows_text}` +
      (d.editable ? "" : ". The set-up is fixed once the test has started.") + "</p>";
    body.innerHTML = html;
    body.querySelectorAll("input,select").forEach((el) => {
      el.addEventListener("input", checkSetup);
      el.addEventListener("change", checkSetup);
    });
    $("#setup-apply").disabled = true;
  }
  function setupRequest() {
    const s = JSON.parse(JSON.stringify(setupData.setup));
    document.querySelectorAll("#setup-body [data-ch]").forEach((el) => {
      const c = s.channels[Number(el.dataset.ch)];
      c[el.dataset.key] = el.dataset.key === "point" ? el.value : Number(el.value);
    });
    s.trigger.level = Number($("#trig-level").value);
    s.trigger.pretrigger_samples = Number($("#trig-pre").value);
    const req = { setup: s };
    const wf = $("#win-force").value.trim(), we = $("#win-exp").value.trim();
    if (wf || we) req.windows = { force: wf || null, exp: we || null };
    return req;
  }
  let checkSeq = 0;
  function checkSetup() {
    const st = $("#setup-status");
    const mine = ++checkSeq;  // answers can overtake each other: only the latest one counts
    api("/api/setup/check", setupRequest()).then((r) => {
      if (mine !== checkSeq) return;
      st.textContent = `valid for this analyser (bandwidth ${r.bandwidth_hz.toFixed(0)} Hz; windows ${r.windows_text})`;
      st.className = "muted";
      $("#setup-apply").disabled = !(inControl && setupData.editable);
    }).catch((e) => {
      if (mine !== checkSeq) return;
      st.textContent = e.message; st.className = "bad"; $("#setup-apply").disabled = true;
    });
  }
  $("#setup-apply").addEventListener("click", () => {
    api("/api/action", Object.assign({ action: "setup" }, setupRequest()))
      .then(() => { $("#setup-status").textContent = "set-up applied"; })
      .catch((e) => { $("#setup-status").textContent = e.message; $("#setup-status").className = "bad"; });
  });

  // -- the event stream -------------------------------------------------------------------------------
  function connect() {
    const es = new EventSource("/api/events?token=" + encodeURIComponent(token));
    es.addEventListener("state", (ev) => {
      $("#link").textContent = "live"; $("#link").className = "badge good";
      state = JSON.parse(ev.data);
      render();
    });
    es.onerror = () => {
      $("#link").textContent = "link lost: reconnecting"; $("#link").className = "badge bad";
      if (state) { state.allowed = []; render(); }  // nothing can be sent until the link is back
    };
  }
  api("/api/blob/geometry").then((g) => { geometry = g; drawGeometry(); }).catch(() => {});
  lease(false);
  connect();
})();
