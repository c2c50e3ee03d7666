/* impactlab test report: draws the plots from window.REPORT_DATA and animates the mode shapes.
   No network: plotly.js is loaded from the report folder. */
(function () {
  "use strict";
  var D = window.REPORT_DATA;
  var CONFIG = { responsive: true, displaylogo: false };
  var COLORS = ["#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf",
                "#7f7f7f", "#bcbd22"];
  var FONT = { family: "DejaVu Sans, Arial, sans-serif", size: 13 };

  function el(name) { return document.querySelector('[data-plot="' + name + '"]'); }
  function color(i) { return COLORS[i % COLORS.length]; }
  function axis(title, extra) {
    var a = { title: { text: title }, showgrid: true, gridcolor: "#e5e5e5", zeroline: false, linecolor: "#444",
              mirror: true, ticks: "outside" };
    for (var k in extra) { a[k] = extra[k]; }
    return a;
  }
  function layout(extra) {
    var l = { font: FONT, margin: { l: 70, r: 20, t: 20, b: 50 }, plot_bgcolor: "#fff", paper_bgcolor: "#fff",
              legend: { font: { size: 12 } } };
    for (var k in extra) { l[k] = extra[k]; }
    return l;
  }
  function vline(x, y0, y1, dash, c, yref) {
    return { type: "line", x0: x, x1: x, y0: y0, y1: y1, xref: "x", yref: yref || "paper",
             line: { color: c || "#888", width: 1, dash: dash || "dot" } };
  }
  var FREQ = "frequency [Hz]";

  /* FRFs: the plot holds the first IN_PLOT FRFs (the strongest, VISIBLE of them drawn); the picker adds any
     other one. Trace 2k and 2k+1 of the FRF plot (magnitude, phase) go with trace k of the coherence. */
  var IN_PLOT = 16;
  function frfTraces(t, i, vis) {
    return [{ x: D.frf.freq_hz, y: t.mag_db, name: t.name, legendgroup: t.name, visible: vis, type: "scatter",
              mode: "lines", line: { width: 1.2, color: color(i) }, xaxis: "x", yaxis: "y" },
            { x: D.frf.freq_hz, y: t.phase_deg, name: t.name, legendgroup: t.name, showlegend: false, visible: vis,
              type: "scatter", mode: "lines", line: { width: 1, color: color(i) }, xaxis: "x", yaxis: "y2" }];
  }
  function cohTrace(t, i, vis) {
    return { x: D.frf.freq_hz, y: t.coh, name: t.name, visible: vis, type: "scatter", mode: "lines",
             line: { width: 1, color: color(i) } };
  }
  function drawFRF() {
    var F = D.frf, data = [], coh = [], shown = [];
    var unit = F.unit ? " re 1 " + F.unit : "";
    F.traces.slice(0, IN_PLOT).forEach(function (t, i) {
      var vis = t.visible ? true : "legendonly";
      data = data.concat(frfTraces(t, i, vis));
      if (F.has_coherence) { coh.push(cohTrace(t, i, vis)); }
      shown.push(i);
    });
    var frfDiv = el("frf");
    var picker = document.getElementById("frf-picker");
    F.traces.forEach(function (t, i) {
      var o = document.createElement("option");
      o.value = String(i); o.textContent = t.name + (i < IN_PLOT ? " (in the legend)" : "");
      picker.appendChild(o);
    });
    var p = Plotly.newPlot(frfDiv, data, layout({
      xaxis: axis(FREQ, { anchor: "y2", range: D.modal.band_hz }),
      yaxis: axis("magnitude [dB" + unit + "]", { domain: [0.38, 1] }),
      yaxis2: axis("phase [deg]", { domain: [0, 0.3], range: [-185, 185], tickvals: [-180, -90, 0, 90, 180] }),
      legend: { font: { size: 11 }, title: { text: "FRF (output / reference)" } }
    }), CONFIG);
    var cohDiv = el("coherence");
    var q = F.has_coherence ? Plotly.newPlot(cohDiv, coh, layout({ xaxis: axis(FREQ, { range: D.modal.band_hz }),
        yaxis: axis("coherence [-]", { range: [0, 1.05] }), showlegend: false }), CONFIG) : Promise.resolve();
    return [p, Promise.all([p, q]).then(function () {
      picker.addEventListener("change", function () {
        var i = Number(picker.value), k = shown.indexOf(i);
        if (k >= 0) {
          Plotly.restyle(frfDiv, { visible: true }, [2 * k, 2 * k + 1]);
        } else {
          Plotly.addTraces(frfDiv, frfTraces(F.traces[i], i, true));
          if (F.has_coherence) { Plotly.addTraces(cohDiv, cohTrace(F.traces[i], i, true)); }
          shown.push(i);
        }
      });
      if (!F.has_coherence) { return; }
      frfDiv.on("plotly_restyle", function (ev) {   // legend clicks: the coherence follows the FRFs
        var upd = ev[0], idx = ev[1];
        if (!upd || !("visible" in upd) || !idx) { return; }
        var vis = [], tr = [];
        idx.forEach(function (k, j) {
          if (k % 2 === 0) { tr.push(k / 2); vis.push(Array.isArray(upd.visible) ? upd.visible[j % upd.visible.length] : upd.visible); }
        });
        if (tr.length) { Plotly.restyle(cohDiv, { visible: vis }, tr); }
      });
      frfDiv.on("plotly_relayout", function (ev) {  // zoom: same frequency range
        if ("xaxis.range[0]" in ev) { Plotly.relayout(cohDiv, { "xaxis.range": [ev["xaxis.range[0]"], ev["xaxis.range[1]"]] }); }
        else if (ev["xaxis.autorange"]) { Plotly.relayout(cohDiv, { "xaxis.autorange": true }); }
      });
    })];
  }

  function drawPoints() {
    var P = D.points;
    if (!P || !P.length) { return []; }
    var spec = [], shapes = [], force = [], resp = [];
    P.forEach(function (p, i) {
      var s = p.spectrum;
      var marks = [];
      [["f10_hz", "-10 dB", "dash"], ["f20_hz", "-20 dB", "dot"]].forEach(function (m) {
        if (s[m[0]] !== null) {
          shapes.push(vline(s[m[0]], 0, 1, m[2], color(i)));
          marks.push(m[1] + " at " + s[m[0]].toFixed(0) + " Hz");
        }
      });
      spec.push({ x: s.freq_hz, y: s.gff_db, name: p.point + " (" + p.n_hits + " hits; " + (marks.join(", ") || "no drop") + ")",
                  type: "scatter", mode: "lines", line: { color: color(i), width: 1.3 } });
      force.push({ x: p.force.t_ms, y: p.force.y, name: p.point, type: "scatter", mode: "lines", line: { color: color(i) } });
      p.responses.forEach(function (r, j) {
        // one colour per response channel (the same channel has the same colour at every point), the dash per point
        resp.push({ x: r.t_ms, y: r.y, name: "hit at " + p.point + ": " + r.name + (r.unit ? " [" + r.unit + "]" : ""),
                    visible: i === 0 ? true : "legendonly", type: "scatter", mode: "lines",
                    line: { color: color(j), width: 1, dash: ["solid", "dash", "dot", "dashdot"][i % 4] } });
      });
    });
    var runit = (P[0].responses[0] && P[0].responses[0].unit) ? P[0].responses[0].unit : "EU";
    return [
      Plotly.newPlot(el("force-spectrum"), spec, layout({ xaxis: axis(FREQ), yaxis: axis("force autospectrum [dB re 1 N\u00b2/Hz]"),
                                                          shapes: shapes, legend: { font: { size: 11 } } }), CONFIG),
      Plotly.newPlot(el("force-time"), force, layout({ xaxis: axis("time after trigger [ms]"), yaxis: axis("force [N]") }), CONFIG),
      Plotly.newPlot(el("response-time"), resp, layout({ xaxis: axis("time after trigger [ms]"), yaxis: axis("response [" + runit + "]") }), CONFIG)
    ];
  }

  function drawStabilization() {
    var S = D.modal.stabilization, data = [], shapes = [];
    var SYM = { "new": ["circle-open", "#aaaaaa", "new pole"], "freq": ["x-thin-open", "#ff7f0e", "stable frequency"],
                "freq+damp": ["diamond-open", "#1f77b4", "stable frequency + damping"],
                "freq+damp+mac": ["circle", "#d62728", "stable frequency + damping + vector"] };
    data.push({ x: S.freq_hz, y: S.summed_db, name: "summed FRF", type: "scatter", mode: "lines", hoverinfo: "skip",
                line: { color: "#333", width: 1 }, yaxis: S.classes ? "y2" : "y" });
    if (S.classes) {
      Object.keys(SYM).forEach(function (k) {
        var c = S.classes[k];
        if (!c || !c.freq_hz.length) { return; }
        data.push({ x: c.freq_hz, y: c.order, customdata: c.damping, name: SYM[k][2], type: "scatter", mode: "markers",
                    meta: "poles", hovertemplate: "%{x:.4f} Hz, \u03b6 %{customdata:.3%}, order %{y}<extra>" + SYM[k][2] + "</extra>",
                    marker: { symbol: SYM[k][0], color: SYM[k][1], size: k === "new" ? 5 : 7, line: { width: 1, color: SYM[k][1] } } });
      });
      data.push({ x: [], y: [], name: "picked", type: "scatter", mode: "markers", meta: "picked", hoverinfo: "skip",
                  marker: { symbol: "circle-open", size: 15, color: "#000", line: { width: 2, color: "#000" } } });
    }
    S.fitted_hz.forEach(function (f) { shapes.push(vline(f, 0, 1, "dot", "#2ca02c")); });
    // the legend sits above the plot area, never over the pole columns
    var lay = { shapes: shapes, xaxis: axis(FREQ), hovermode: "closest",
                legend: { orientation: "h", x: 0, xanchor: "left", y: 1.02, yanchor: "bottom" } };
    if (S.classes) {
      lay.yaxis = axis("model order [modes]");
      lay.yaxis2 = axis("summed FRF [dB]", { overlaying: "y", side: "right", showgrid: false, tickmode: "auto" });
      lay.margin = { l: 70, r: 70, t: 70, b: 50 };
    } else {
      lay.yaxis = axis("summed FRF [dB]");
      lay.margin = { l: 70, r: 20, t: 50, b: 50 };
    }
    var div = el("stabilization");
    var p = Plotly.newPlot(div, data, layout(lay), CONFIG);
    return S.classes ? p.then(function () { setupPicking(div, data.length - 1); }) : p;
  }

  /* Pole picking: a click on a pole marker picks it (a ring marks it), a second click unpicks it; the
     picks are listed under the diagram and saved as poles.json (schema impactlab.poles/1, read by
     'python -m analysis fit INPUT --poles poles.json'). */
  var PICKS_SCHEMA = "impactlab.poles/1";
  function setupPicking(div, ringTrace) {
    var picks = [], list = document.getElementById("pick-list");
    var save = document.getElementById("save-picks"), clear = document.getElementById("clear-picks");
    function key(p) { return p.freq_hz + "@" + p.order; }
    function document_() {
      return { schema: PICKS_SCHEMA, input: D.meta.input, band_hz: D.modal.stabilization.band_hz,
               poles: picks.slice().sort(function (a, b) { return a.freq_hz - b.freq_hz; }) };
    }
    function refresh() {
      var sorted = document_().poles;
      list.innerHTML = "";
      sorted.forEach(function (q) {
        var li = document.createElement("li");
        li.textContent = q.freq_hz.toFixed(4) + " Hz, \u03b6 " + (100 * q.damping).toFixed(3) + " %, model order " + q.order;
        list.appendChild(li);
      });
      save.disabled = clear.disabled = !picks.length;
      div.dataset.picks = String(picks.length);
      return Plotly.restyle(div, { x: [picks.map(function (q) { return q.freq_hz; })],
                                   y: [picks.map(function (q) { return q.order; })] }, [ringTrace]);
    }
    div.on("plotly_click", function (ev) {
      var pt = (ev.points || []).filter(function (q) { return q.data.meta === "poles" || q.data.meta === "picked"; })[0];
      if (!pt) { return; }
      var q;
      if (pt.data.meta === "picked") { q = picks[pt.pointIndex]; }
      else { q = { freq_hz: pt.x, damping: pt.customdata, order: pt.y }; }
      var k = key(q), at = picks.map(key).indexOf(k);
      if (at >= 0) { picks.splice(at, 1); } else { picks.push(q); }
      refresh();
    });
    clear.addEventListener("click", function () { picks = []; refresh(); });
    save.addEventListener("click", function () {
      var blob = new Blob([JSON.stringify(document_(), null, 1) + "\n"], { type: "application/json" });
      var a = document.createElement("a");
      a.href = URL.createObjectURL(blob);
      a.download = "poles.json";
      document.body.appendChild(a);
      a.click();
      a.remove();
    });
    window.impactlabPicks = function () { return document_(); };
    div.dataset.picks = "0";
  }

  function drawIndicator() {
    var I = D.modal.indicator, data = [], shapes = [];
    var cols = ["#1f77b4", "#d62728", "#2ca02c", "#ff7f0e"];
    I.cmif_db.forEach(function (y, k) {
      data.push({ x: I.freq_hz, y: y, name: "CMIF " + (k + 1), type: "scatter", mode: "lines",
                  line: { color: cols[k % cols.length], width: 1.2 } });
    });
    if (I.mif) {
      data.push({ x: I.freq_hz, y: I.mif, name: "MIF", type: "scatter", mode: "lines", yaxis: "y2",
                  line: { color: "#9467bd", width: 1.2, dash: "dot" } });
    }
    D.modal.stabilization.fitted_hz.forEach(function (f) { shapes.push(vline(f, 0, 1, "dot", "#2ca02c")); });
    var unit = I.unit ? " re 1 " + I.unit : "";
    var lay = { shapes: shapes, xaxis: axis(FREQ), yaxis: axis("singular value [dB" + unit + "]"),
                legend: { orientation: "h", x: 0, y: 1.02, yanchor: "bottom" }, margin: { l: 70, r: 70, t: 40, b: 50 } };
    if (I.mif) { lay.yaxis2 = axis("MIF [-]", { overlaying: "y", side: "right", range: [0, 1.05], showgrid: false }); }
    return Plotly.newPlot(el("cmif"), data, layout(lay), CONFIG);
  }

  function setupLogFrequency() {
    var box = document.getElementById("log-frequency");
    if (!box) { return []; }
    box.addEventListener("change", function () {
      var upd = { "xaxis.type": box.checked ? "log" : "linear", "xaxis.autorange": true };
      ["stabilization", "cmif"].forEach(function (name) { if (el(name)) { Plotly.relayout(el(name), upd); } });
    });
    return [];
  }

  function drawSynthesis() {
    var S = D.modal.synthesis, data = [];
    S.frfs.forEach(function (f, i) {
      data.push({ x: S.freq_hz, y: f.measured_db, name: "measured " + f.name, type: "scatter", mode: "lines",
                  line: { color: color(i), width: 1.3 } });
      data.push({ x: S.freq_hz, y: f.synth_db, name: "synthesised " + f.name, type: "scatter", mode: "lines",
                  line: { color: color(i), width: 1.3, dash: "dash" } });
    });
    data.push({ x: S.freq_hz, y: S.rel_error_db, name: "relative error, all FRFs", type: "scatter", mode: "lines",
                line: { color: "#000", width: 1 }, yaxis: "y2" });
    var unit = D.frf.unit ? " re 1 " + D.frf.unit : "";
    return Plotly.newPlot(el("synthesis"), data, layout({
      xaxis: axis(FREQ, { anchor: "y2" }), yaxis: axis("magnitude [dB" + unit + "]", { domain: [0.36, 1] }),
      yaxis2: axis("relative error [dB]", { domain: [0, 0.28] }), legend: { font: { size: 11 } } }), CONFIG);
  }

  function drawMAC() {
    var M = D.modal.automac, modes = D.modal.modes;
    var names = modes.map(function (m) { return m.n + ": " + m.freq_hz.toFixed(1) + " Hz"; });
    var ann = [];
    if (names.length <= 16) {
      M.forEach(function (row, i) { row.forEach(function (v, j) {
        ann.push({ x: names[j], y: names[i], text: v.toFixed(2), showarrow: false,
                   font: { size: 11, color: v > 0.5 ? "#000" : "#fff" } }); }); });
    }
    return Plotly.newPlot(el("automac"), [{ z: M, x: names, y: names, type: "heatmap", zmin: 0, zmax: 1,
                                            colorscale: "Viridis", colorbar: { title: { text: "MAC [-]" } } }],
                          layout({ xaxis: axis("mode", { type: "category" }), yaxis: axis("mode", { type: "category", autorange: "reversed" }),
                                   annotations: ann, margin: { l: 120, r: 20, t: 20, b: 110 } }), CONFIG);
  }

  function drawDiagnosis() {
    var G = D.diagnosis, div = el("diagnosis");
    if (!G || !div) { return []; }
    var causes = (G.causes || []).slice().reverse();  // the largest gain on top
    return [Plotly.newPlot(div, [
      { y: causes.map(function (c) { return c.effect; }), x: causes.map(function (c) { return c.gain_db; }),
        type: "bar", orientation: "h", name: "gain",
        marker: { color: causes.map(function (c) { return c.significant ? "#1f77b4" : "#aaaaaa"; }) } }
    ], layout({ yaxis: axis("", { type: "category", automargin: true }), xaxis: axis("gain [dB]"), showlegend: false,
                margin: { l: 150, r: 20, t: 10, b: 50 } }), CONFIG)]
      .concat(drawDiagnosisBands(G));
  }

  /* the rows of the diagnosis' "bands" (simulation and extension per band, as bands.png draws them); a
     diagnosis written before they existed has the simulation's alone in comparison.bands */
  function drawDiagnosisBands(G) {
    var div = el("diagnosis-bands");
    var rows = G.bands || ((G.comparison || {}).bands || []).map(function (b) {
      return { lo_hz: b.lo_hz, hi_hz: b.hi_hz, simulation_db: b.error_db, extended_db: null };
    });
    if (!div || !rows.length) { return []; }
    function steps(key) {
      var x = [], y = [];
      rows.forEach(function (b) {  // log axis: a band from 0 Hz starts at a hundredth of its top
        x.push(b.lo_hz > 0 ? b.lo_hz : b.hi_hz / 100, b.hi_hz, null); y.push(b[key], b[key], null);
      });
      return { x: x, y: y };
    }
    var sim = steps("simulation_db"), ext = steps("extended_db");
    var traces = [{ x: sim.x, y: sim.y, type: "scatter", mode: "lines", name: "simulation",
                    line: { color: "#d62728", width: 3 } }];
    if (rows[0].extended_db !== null) {
      traces.push({ x: ext.x, y: ext.y, type: "scatter", mode: "lines", name: "extended",
                    line: { color: "#1f77b4", width: 3, dash: "dash" } });
    }
    return [Plotly.newPlot(div, traces, layout({ xaxis: axis(FREQ, { type: "log" }), yaxis: axis("error [dB]") }),
                           CONFIG)];
  }

  function drawLinearity() {
    var Q = D.quality, div = el("linearity");
    if (!Q || !div || !(Q.linearity_curves || []).length) { return []; }
    var traces = Q.linearity_curves.map(function (c, i) {
      return { x: c.freq_hz, y: c.db, type: "scatter", mode: "lines", name: c.level.toPrecision(3) + " (" + c.frf + ")",
               line: { color: color(i), width: 1.5 } };
    });
    return [Plotly.newPlot(div, traces, layout({ xaxis: axis(FREQ), yaxis: axis("|H1| [dB]") }), CONFIG)];
  }

  function drawReciprocity() {
    var Q = D.quality, div = el("reciprocity");
    if (!Q || !div || !(Q.reciprocity_curves || []).length) { return []; }
    var traces = [];
    Q.reciprocity_curves.forEach(function (c, i) {
      traces.push({ x: c.ij.freq_hz, y: c.ij.db, type: "scatter", mode: "lines", name: "H_ij " + c.pair,
                    line: { color: color(i), width: 1.5 } });
      traces.push({ x: c.ji.freq_hz, y: c.ji.db, type: "scatter", mode: "lines", name: "H_ji " + c.pair,
                    line: { color: color(i), width: 1.5, dash: "dot" } });
    });
    return [Plotly.newPlot(div, traces, layout({ xaxis: axis(FREQ), yaxis: axis("|H| [dB]") }), CONFIG)];
  }

  /* ---- mode shapes: a small orthographic 3-D view on a canvas (no WebGL needed) ---- */
  function ModeView(canvas, S) {
    var g = S.geometry, xyz = g.xyz, n = xyz.length;
    var lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    xyz.forEach(function (p) { for (var a = 0; a < 3; a++) { lo[a] = Math.min(lo[a], p[a]); hi[a] = Math.max(hi[a], p[a]); } });
    var centre = [0, 1, 2].map(function (a) { return (lo[a] + hi[a]) / 2; });
    var size = Math.max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) || 1;
    var measured = {};
    S.dofs.forEach(function (d) { measured[d.node] = true; });
    var st = { mode: 0, phase: 0.6, playing: true, amp: 0.5, speed: 1, az: -0.6, el: 0.45, last: null, frames: 0,
               interpolate: false };
    this.state = st;
    var ctx = canvas.getContext("2d");

    function project(p) {
      var x = p[0] - centre[0], y = p[1] - centre[1], z = p[2] - centre[2];
      var ca = Math.cos(st.az), sa = Math.sin(st.az), ce = Math.cos(st.el), se = Math.sin(st.el);
      var u = ca * x - sa * y, v = sa * x + ca * y;           // about Z
      var sy = ce * z - se * v;                              // tilt towards the viewer
      var s = 0.75 * Math.min(canvas.width, canvas.height) / size;
      return [canvas.width / 2 + s * u, canvas.height / 2 - s * sy];
    }
    /* per node and axis the complex displacement [re, im] of mode k; measured node axes are fixed, with
       st.interpolate every other one becomes the mean of its neighbours along the trace lines (harmonic
       interpolation, Jacobi sweeps), so the wireframe follows the measured points */
    var neighbours = xyz.map(function () { return []; });
    g.lines.forEach(function (l) { neighbours[l[0]].push(l[1]); neighbours[l[1]].push(l[0]); });
    var cache = {};
    function nodeShape(k) {
      var key = k + (st.interpolate ? "i" : "");
      if (cache[key]) { return cache[key]; }
      var m = S.modes[k], u = xyz.map(function () { return [[0, 0], [0, 0], [0, 0]]; });
      var fixed = xyz.map(function () { return [false, false, false]; });
      (g.supports || []).forEach(function (n) { fixed[n] = [true, true, true]; });
      S.dofs.forEach(function (d, i) {
        u[d.node][d.axis] = [d.sign * m.re[i], d.sign * m.im[i]];
        fixed[d.node][d.axis] = true;
      });
      if (st.interpolate) {
        for (var sweep = 0; sweep < 400; sweep++) {
          var next = u.map(function (row) { return row.map(function (c) { return c.slice(); }); });
          for (var n = 0; n < u.length; n++) {
            var nb = neighbours[n];
            if (!nb.length) { continue; }
            for (var a = 0; a < 3; a++) {
              if (fixed[n][a]) { continue; }
              var re = 0, im = 0;
              nb.forEach(function (j) { re += u[j][a][0]; im += u[j][a][1]; });
              next[n][a] = [re / nb.length, im / nb.length];
            }
          }
          u = next;
        }
      }
      cache[key] = u;
      return u;
    }
    function displaced(c) {
      var u = nodeShape(st.mode), k = st.amp * 0.3 * size;
      return xyz.map(function (p, n) {
        return [0, 1, 2].map(function (a) { return p[a] + k * (u[n][a][0] * c.cos - u[n][a][1] * c.sin); });
      });
    }
    function draw() {
      ctx.fillStyle = "#fff"; ctx.fillRect(0, 0, canvas.width, canvas.height);
      var und = xyz.map(project);
      var def = displaced({ cos: Math.cos(st.phase), sin: Math.sin(st.phase) }).map(project);
      ctx.lineWidth = 1; ctx.strokeStyle = "#c8c8c8";
      g.lines.forEach(function (l) { ctx.beginPath(); ctx.moveTo(und[l[0]][0], und[l[0]][1]); ctx.lineTo(und[l[1]][0], und[l[1]][1]); ctx.stroke(); });
      ctx.lineWidth = 2.5; ctx.strokeStyle = "#1f5fa8";
      g.lines.forEach(function (l) { ctx.beginPath(); ctx.moveTo(def[l[0]][0], def[l[0]][1]); ctx.lineTo(def[l[1]][0], def[l[1]][1]); ctx.stroke(); });
      ctx.fillStyle = "#c8c8c8";
      for (var j = 0; j < n; j++) { ctx.beginPath(); ctx.arc(und[j][0], und[j][1], 2, 0, 2 * Math.PI); ctx.fill(); }
      for (var i = 0; i < n; i++) {
        ctx.fillStyle = measured[i] ? "#d62728" : "#1f5fa8";
        ctx.beginPath(); ctx.arc(def[i][0], def[i][1], measured[i] ? 4 : 2, 0, 2 * Math.PI); ctx.fill();
      }
      var m = D.modal.modes[st.mode];
      ctx.fillStyle = "#111"; ctx.font = "16px DejaVu Sans, Arial, sans-serif";
      ctx.fillText("mode " + m.n + ":  f = " + m.freq_hz.toFixed(2) + " Hz,  \u03b6 = " + m.damping_pct.toFixed(2) + " %", 14, 24);
      ctx.font = "13px DejaVu Sans, Arial, sans-serif"; ctx.fillStyle = "#555";
      ctx.fillText("geometry: " + g.name + "   (red: measured points)", 14, 44);
      // axis triad
      var o = [60, canvas.height - 50], names = ["X", "Y", "Z"], cols = ["#d62728", "#2ca02c", "#1f77b4"];
      for (var a = 0; a < 3; a++) {
        var e = [centre[0], centre[1], centre[2]]; e[a] += 0.12 * size;
        var p0 = project(centre), p1 = project(e);
        var dx = p1[0] - p0[0], dy = p1[1] - p0[1], k = 34 / (0.75 * Math.min(canvas.width, canvas.height) * 0.12);
        ctx.strokeStyle = cols[a]; ctx.lineWidth = 2; ctx.beginPath(); ctx.moveTo(o[0], o[1]);
        ctx.lineTo(o[0] + dx * k, o[1] + dy * k); ctx.stroke();
        ctx.fillStyle = cols[a]; ctx.fillText(names[a], o[0] + dx * k * 1.25 - 4, o[1] + dy * k * 1.25 + 4);
      }
      st.frames++;
      canvas.dataset.frames = String(st.frames);
    }
    function tick(ts) {
      if (st.last !== null && st.playing) { st.phase += 2 * Math.PI * 0.5 * st.speed * Math.min(0.1, (ts - st.last) / 1000); }
      st.last = ts;
      if (st.playing || st.dirty) { st.dirty = false; draw(); }
      window.requestAnimationFrame(tick);
    }
    var drag = null;
    canvas.addEventListener("mousedown", function (e) { drag = [e.clientX, e.clientY, st.az, st.el]; });
    window.addEventListener("mouseup", function () { drag = null; });
    window.addEventListener("mousemove", function (e) {
      if (!drag) { return; }
      st.az = drag[2] + (e.clientX - drag[0]) * 0.01;
      st.el = Math.max(-1.5, Math.min(1.5, drag[3] + (e.clientY - drag[1]) * 0.01));
      st.dirty = true;
    });
    this.set = function (k, v) { st[k] = v; st.dirty = true; };
    draw();
    window.requestAnimationFrame(tick);
  }

  function setupShapes() {
    var S = D.shapes, canvas = el("mode-shapes");
    var sel = document.getElementById("mode-select");
    D.modal.modes.forEach(function (m, i) {
      var o = document.createElement("option");
      o.value = String(i); o.textContent = m.n + ": " + m.freq_hz.toFixed(2) + " Hz";
      sel.appendChild(o);
    });
    if (!S.modes.length) { return; }
    var view = new ModeView(canvas, S);
    window.impactlabModeView = view;
    sel.addEventListener("change", function () { view.set("mode", Number(sel.value)); });
    var btn = document.getElementById("play");
    btn.addEventListener("click", function () {
      view.set("playing", !view.state.playing);
      btn.textContent = view.state.playing ? "pause" : "play";
    });
    document.getElementById("amplitude").addEventListener("input", function (e) { view.set("amp", Number(e.target.value)); });
    document.getElementById("speed").addEventListener("input", function (e) { view.set("speed", Number(e.target.value)); });
    document.getElementById("interpolate").addEventListener("change", function (e) { view.set("interpolate", e.target.checked); });
  }

  var jobs = [];
  function attempt(name, fn) {
    try { jobs = jobs.concat(fn()); } catch (err) { console.error("report: cannot draw " + name + ": " + err); }
  }
  /* the drawers by name: every report section (analysis/report_html/sections.py) names its own, and the
     document lists those of the sections shown, in order (D.drawers) */
  var DRAWERS = {
    "points": drawPoints,
    "frf": drawFRF,
    "stabilization": drawStabilization,
    "indicator": drawIndicator,
    "log-frequency": setupLogFrequency,
    "synthesis": drawSynthesis,
    "automac": drawMAC,
    "mode-shapes": setupShapes,
    "diagnosis": drawDiagnosis,
    "linearity": drawLinearity,
    "reciprocity": drawReciprocity
  };
  (D.drawers || []).forEach(function (name) {
    attempt(name, DRAWERS[name] || function () { throw new Error("report.js has no drawer " + name); });
  });
  Promise.all(jobs).then(function () {
    document.body.dataset.drawnMs = String(Math.round(performance.now()));  // for benchmarks
    document.body.dataset.ready = "1";
  },
                         function (err) { console.error("report: a plot failed: " + err); document.body.dataset.ready = "error"; });
})();
