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
      el("dd", { id: "settling" }, settle),
      el("dt", {}, "isolators"),
      el(
        "dd",
        { id: "isolators" },
        el("ul", { class: "plain" }, Object.entries(ts.isolators || {}).map(([name, iso]) => el("li", { title: name }, iso.label)))
      )
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

// SI unit -> [unit shown, factor from SI]: the unit the study was written in for that quantity (a study
// that writes its accelerations in g reads its stage accelerations in g), else the page's default.
function studyUnits(design) {
  const units = {};
  for (const p of design.parameters) {
    if (!p.categorical && p.display_scale !== 1 && p.unit && !(p.unit in units)) units[p.unit] = [p.display_unit, 1 / p.display_scale];
  }
  return (si) => units[si] || displayUnit(si);
}

function isolatorPlace(ts, iso) {
  const found = ts.isolators && ts.isolators[iso];
  return found ? found.place : iso;
}

// The panels of a case, each with its long name, unit and series (full resolution, display units).
function casePanels(ts, unitOf) {
  const panels = []; // {title, unit, series: [{name, y, colour, dash}]}
  const panel = (title, si, series) => {
    const [unit, factor] = unitOf(si);
    panels.push({ title, unit, series: series.map((x) => ({ ...x, y: x.y.map((v) => (v === null ? null : v * factor)) })) });
  };
  panel("displacement of the machine c.g.", "m", Object.entries(ts.displacement).map(([a, y]) => ({ name: `c.g. ${a}`, y, colour: AXIS_COLOURS[a] })));
  const points = Object.entries(ts.point_displacement);
  if (points.length) {
    panel(
      "displacement of the points of interest",
      "m",
      points.flatMap(([p, axes], k) => Object.entries(axes).map(([a, y]) => ({ name: `${p} ${a}`, y, colour: AXIS_COLOURS[a], dash: DASHES[k % DASHES.length] })))
    );
  }
  panel("rotation of the machine base", "rad", Object.entries(ts.rotation).map(([r, y]) => ({ name: `rotation ${r}`, y, colour: AXIS_COLOURS[r] })));
  panel(
    "dynamic isolator force about the preload",
    "N",
    Object.entries(ts.isolator_force).flatMap(([iso, axes], k) =>
      Object.entries(axes).map(([a, y]) => ({ name: `${isolatorPlace(ts, iso)} ${a}`, y, colour: AXIS_COLOURS[a], dash: DASHES[k % DASHES.length] }))
    )
  );
  const stages = Object.entries(ts.stages || {});
  const stageColours = (k) => PALETTE[(k + 3) % PALETTE.length];
  if (stages.length) {
    panel("stage position along its axis", "m", stages.map(([st, p], k) => ({ name: `stage ${st}`, y: p.position, colour: stageColours(k) })));
    panel("stage velocity along its axis", "m/s", stages.map(([st, p], k) => ({ name: `stage ${st}`, y: p.velocity, colour: stageColours(k) })));
    panel("stage acceleration along its axis", "m/s^2", stages.map(([st, p], k) => ({ name: `stage ${st}`, y: p.acceleration, colour: stageColours(k) })));
  }
  return panels;
}

function drawTraces(ts, panels) {
  const step = Math.max(1, Math.ceil(ts.time.length / MAX_POINTS));
  const t = thin(ts.time, step);
  const n = panels.length;
  const gap = 0.035;
  const traces = [];
  // each panel 210 px high, or as high as its legend's entries (about 19 px each) need
  const heights = panels.map((p) => Math.max(210, 19 * p.series.length + 20));
  const plotHeight = heights.reduce((a, b) => a + b, 0);
  const tops = heights.map((_, i) => 1 - heights.slice(0, i).reduce((a, b) => a + b, 0) / plotHeight);
  const layout = {
    height: plotHeight + 80,
    margin: { t: 30, r: 20, b: 50, l: 90 },
    shapes: [],
    annotations: [],
    xaxis: { title: { text: "time [s]" }, anchor: `y${n === 1 ? "" : n}` },
  };
  // one legend per panel, beside it: a panel's entries are read next to its lines
  panels.forEach((p, i) => {
    const axis = i === 0 ? "y" : `y${i + 1}`;
    const legend = i === 0 ? "legend" : `legend${i + 1}`;
    const top = tops[i];
    const bottom = top - heights[i] / plotHeight;
    for (const sr of p.series) {
      traces.push({
        type: "scatter",
        mode: "lines",
        name: sr.name,
        x: t,
        y: thin(sr.y, step),
        line: { color: sr.colour, dash: sr.dash || "solid", width: 1.4 },
        xaxis: "x",
        yaxis: axis,
        legend,
      });
    }
    layout[i === 0 ? "yaxis" : `yaxis${i + 1}`] = {
      title: { text: `${p.title.replace(/ (of|about|along) /, "<br>$1 ")}${p.unit ? ` [${p.unit}]` : ""}`, font: { size: 10 } },
      domain: [bottom + gap / 2, top - gap / 2],
      zeroline: true,
    };
    layout[legend] = { x: 1.01, xanchor: "left", y: top - gap / 2, yanchor: "top", font: { size: 10 }, tracegroupgap: 2 };
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

// The traces as CSV, every sample, in the units the page shows them in.
function tracesCsv(ts, panels) {
  const cell = (v) => (v === null || v === undefined ? "" : String(v));
  const quote = (text) => (/[",\n]/.test(text) ? `"${text.replaceAll('"', '""')}"` : text);
  const columns = panels.flatMap((p) => p.series.map((sr) => [`${p.title}: ${sr.name}${p.unit ? ` [${p.unit}]` : ""}`, sr.y]));
  const lines = [["time [s]", ...columns.map(([h]) => h)].map(quote).join(",")];
  ts.time.forEach((time, i) => lines.push([cell(time), ...columns.map(([, y]) => cell(y[i]))].join(",")));
  return lines.join("\n") + "\n";
}

function downloadText(text, filename, type) {
  const url = URL.createObjectURL(new Blob([text], { type }));
  const a = el("a", { href: url, download: filename });
  document.body.appendChild(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 10000);
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
    const panels = casePanels(ts, studyUnits(design));
    drawTraces(ts, panels);
    const csv = $("#traces-csv");
    csv.disabled = false;
    csv.addEventListener("click", () => downloadText(tracesCsv(ts, panels), `${study.name}-case${caseNo}-traces.csv`, "text/csv"));
  } catch (err) {
    showError("#error", err);
    fill($("#facts"));
  }
}

main();
