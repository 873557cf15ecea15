// /ui/studies/{id}/cases/{case}: one case recomputed with its time histories: c.g. and point motion,
// rotations, dynamic isolator forces, the stage profiles underneath on the same time axis, the natural
// modes named by their dominant motion, the settling marked.
"use strict";

const caseMatch = location.pathname.match(/\/ui\/studies\/([^/]+)\/cases\/(\d+)/);
const studyId = caseMatch ? decodeURIComponent(caseMatch[1]) : null;
const caseNo = caseMatch ? Number(caseMatch[2]) : null;
const MAX_POINTS = 4000; // samples per trace drawn

const AXIS_COLOURS = { x: "#1f77b4", y: "#d62728", z: "#2ca02c", rx: "#1f77b4", ry: "#d62728", rz: "#2ca02c" };
const DASHES = ["solid", "dash", "dot", "dashdot", "longdash", "longdashdot"];

function renderFacts(ts, design, studyName) {
  const units = {};
  for (const p of design.parameters) units[p.name] = p;
  const params = Object.entries(ts.parameters).map(([k, v]) => {
    const p = units[k];
    const shown = typeof v === "number" && p && !p.categorical ? `${fmt(v / p.display_scale)} ${p.display_unit}` : fmt(v);
    return [el("dt", {}, k), el("dd", {}, shown)];
  });
  const settle =
    ts.settling_time === null
      ? "–"
      : `${fmt(ts.settling_time, 3)} s after the last move (at ${fmt(ts.last_move_end + ts.settling_time, 3)} s)` +
        (ts.settled ? "" : ", not settled by the end: a lower bound");
  fill($("#facts"), 
    el(
      "dl",
      { class: "facts" },
      el("dt", {}, "study"),
      el("dd", {}, el("a", { href: `/ui/studies/${studyId}` }, studyName)),
      params,
      el("dt", {}, "status"),
      el("dd", { class: ts.status === "ok" ? "ok" : "error" }, ts.status + (ts.message ? `: ${ts.message}` : "")),
      el("dt", {}, "last move ends"),
      el("dd", {}, ts.last_move_end === null ? "–" : `${fmt(ts.last_move_end, 3)} s`),
      el("dt", {}, "settling"),
      el("dd", { id: "settling" }, settle)
    )
  );
}

function renderModes(ts) {
  const dofs = ["x", "y", "z", "rx", "ry", "rz"];
  fill($("#modes"), 
    el(
      "table",
      { id: "mode-table" },
      el(
        "thead",
        {},
        el("tr", {}, el("th", {}, "mode"), el("th", {}, "motion"), el("th", { class: "num" }, "f [Hz]"), el("th", { class: "num" }, "ζ [%]"), dofs.map((d) => el("th", { class: "num" }, `${d} [%]`)))
      ),
      el(
        "tbody",
        {},
        ts.modes.map((m) =>
          el(
            "tr",
            {},
            el("td", {}, m.mode),
            el("td", {}, el("strong", {}, m.name || "–")),
            el("td", { class: "num" }, fmt(m.frequency, 3)),
            el("td", { class: "num" }, m.damping_ratio === null ? "–" : fmt(100 * m.damping_ratio, 3)),
            dofs.map((d) => el("td", { class: "num" + ((m.energy[d] || 0) > 0.5 ? " best" : "") }, m.energy[d] === null ? "–" : String(Math.round(100 * m.energy[d]))))
          )
        )
      )
    ),
    el("p", { class: "muted" }, "Each mode is named by the motion holding most of its kinetic energy (x surge, y sway, z heave, rx pitch, ry roll, rz yaw); a second one holding a quarter or more is named too.")
  );
}

function thin(values, step) {
  if (step <= 1) return values;
  const out = [];
  for (let i = 0; i < values.length; i += step) out.push(values[i]);
  return out;
}

function drawTraces(ts) {
  const step = Math.max(1, Math.ceil(ts.time.length / MAX_POINTS));
  const t = thin(ts.time, step);
  const scale = (arr, f) => thin(arr, step).map((v) => (v === null ? null : v * f));
  const panels = []; // [title, traces]
  const line = (name, y, colour, dash, group) => ({
    type: "scatter",
    mode: "lines",
    name,
    x: t,
    y,
    line: { color: colour, dash: dash || "solid", width: 1.4 },
    legendgroup: group,
  });
  panels.push(["c.g. [mm]", Object.entries(ts.displacement).map(([a, y]) => line(`c.g. ${a}`, scale(y, 1e3), AXIS_COLOURS[a], "solid", "cg"))]);
  const points = Object.entries(ts.point_displacement);
  if (points.length) {
    panels.push([
      "points [mm]",
      points.flatMap(([p, axes], k) => Object.entries(axes).map(([a, y]) => line(`${p} ${a}`, scale(y, 1e3), AXIS_COLOURS[a], DASHES[(k + 1) % DASHES.length], "points"))),
    ]);
  }
  panels.push(["rotation [mrad]", Object.entries(ts.rotation).map(([r, y]) => line(`rotation ${r}`, scale(y, 1e3), AXIS_COLOURS[r], "solid", "rot"))]);
  panels.push([
    "isolator force, dynamic<br>about the preload [N]",
    Object.entries(ts.isolator_force).flatMap(([iso, axes], k) => Object.entries(axes).map(([a, y]) => line(`${iso} ${a}`, scale(y, 1), AXIS_COLOURS[a], DASHES[k % DASHES.length], "force"))),
  ]);
  const stages = Object.entries(ts.stages || {});
  const stageColours = (k) => PALETTE[(k + 3) % PALETTE.length];
  if (stages.length) {
    panels.push(["stage position [mm]", stages.map(([s, p], k) => line(`stage ${s} position`, scale(p.position, 1e3), stageColours(k), "solid", "stages"))]);
    panels.push(["stage velocity [m/s]", stages.map(([s, p], k) => line(`stage ${s} velocity`, scale(p.velocity, 1), stageColours(k), "solid", "stages"))]);
    panels.push(["stage accel. [m/s²]", stages.map(([s, p], k) => line(`stage ${s} acceleration`, scale(p.acceleration, 1), stageColours(k), "solid", "stages"))]);
  }
  const n = panels.length;
  const traces = [];
  const layout = {
    height: 210 * n + 80,
    margin: { t: 30, r: 20, b: 50, l: 90 },
    grid: { rows: n, columns: 1, pattern: "coupled", roworder: "top to bottom" },
    legend: { orientation: "v", x: 1.01, y: 1, font: { size: 10 } },
    shapes: [],
    annotations: [],
    xaxis: { title: { text: "time [s]" } },
  };
  panels.forEach(([title, ts_], i) => {
    const axis = i === 0 ? "y" : `y${i + 1}`;
    for (const tr of ts_) traces.push({ ...tr, xaxis: "x", yaxis: axis });
    layout[i === 0 ? "yaxis" : `yaxis${i + 1}`] = { title: { text: title, font: { size: 11 } }, zeroline: true };
  });
  const mark = (time, colour, text) => {
    layout.shapes.push({ type: "line", xref: "x", yref: "paper", x0: time, x1: time, y0: 0, y1: 1, line: { color: colour, width: 1.5, dash: "dash" } });
    layout.annotations.push({ xref: "x", yref: "paper", x: time, y: 1.0, yanchor: "bottom", text, showarrow: false, font: { size: 10, color: colour } });
  };
  if (ts.last_move_end !== null) mark(ts.last_move_end, "#555", "last move ends");
  if (ts.settling_time !== null && ts.last_move_end !== null) {
    mark(ts.last_move_end + ts.settling_time, "#1d8a1d", ts.settled ? "settled" : "not settled (lower bound)");
  }
  const node = $("#traces");
  fill(node);
  Plotly.newPlot(node, traces, layout, PLOT_CONFIG);
}

async function main() {
  header("studies");
  $("#title").textContent = `Case ${caseNo}`;
  try {
    const [study, design] = await Promise.all([apiJson(`/studies/${studyId}`), apiJson(`/studies/${studyId}/design`)]);
    fill($("#title"), document.createTextNode(`${study.name} · case ${caseNo}`));
    document.title = `isolab – ${study.name} case ${caseNo}`;
    const ts = await apiJson(`/studies/${studyId}/cases/${caseNo}/timeseries`);
    renderFacts(ts, design, study.name);
    renderModes(ts);
    drawTraces(ts);
  } catch (err) {
    showError("#error", err);
    fill($("#facts"));
  }
}

main();
