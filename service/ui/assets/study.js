// /ui/studies/{id}: definition as written, progress (live), model and error estimate, sweep plot, case
// table with the filter/sort language, downloads.
"use strict";

const studyId = studyIdFromPath();
const PLOT_ROWS = 20000; // the sweep plot reads at most this many cases
const TABLE_ROWS = 200;

let study = null;
let design = null;
let table = null; // {columns, units, rows} of the sweep
let loadedDone = false;

// column -> {unit shown, factor from SI, log axis}
function columnUnit(name) {
  const p = design && design.parameters.find((q) => q.name === name);
  if (p && !p.categorical) return { unit: p.display_unit, factor: 1 / p.display_scale, log: p.scale === "log" };
  if (p) return { unit: "", factor: 1, log: false };
  const [unit, factor] = displayUnit(table ? table.units[name] : "");
  return { unit, factor, log: false };
}

// What a column holds, in words: an output's long name, a parameter's name in words ("stage y
// acceleration"); with its unit.
function longName(name) {
  const known = table && table.long_names && table.long_names[name];
  return known || name.replaceAll("_", " ");
}

function label(name) {
  const u = columnUnit(name).unit;
  return u ? `${longName(name)} [${u}]` : longName(name);
}

function writtenValues(p) {
  if (p.values) return p.values.map((v) => String(v)).join(", ");
  if (p.range) {
    const r = p.range;
    return `${r.start} … ${r.stop}` + (r.num ? `, ${r.num} levels` : "") + (r.scale === "log" ? ", log" : "");
  }
  return "from the design's cases";
}

// ------------------------------------------------------------------------------------------- status
function renderStatus() {
  const s = study;
  fill($("#title"), document.createTextNode(s.name), statusBadge(s.status));
  document.title = `isolab – ${s.name}`;
  fill($("#status"), 
    progressBar(s.progress.done, s.progress.total, s.progress.failed),
    s.note ? el("p", { class: "muted", id: "study-note" }, s.note) : null,
    el(
      "dl",
      { class: "facts" },
      el("dt", {}, "cases"),
      el("dd", {}, `${s.progress.total} (${s.progress.done} done, ${s.progress.failed} failed)`),
      el("dt", {}, "created"),
      el("dd", {}, when(s.created)),
      el("dt", {}, "started"),
      el("dd", {}, when(s.started)),
      el("dt", {}, "finished"),
      el("dd", {}, when(s.finished)),
      s.error ? [el("dt", {}, "error"), el("dd", { class: "error" }, s.error)] : null
    )
  );
}

function renderDefinition() {
  const rows = design.parameters.map((p) =>
    el(
      "tr",
      {},
      el("td", {}, p.name),
      el("td", {}, el("code", {}, p.path)),
      el("td", {}, writtenValues(p)),
      el("td", {}, p.categorical ? "categorical" : p.scale),
      el("td", {}, p.categorical ? "" : p.display_unit)
    )
  );
  const d = design.design;
  const yaml = el("pre", { class: "yaml", id: "definition-yaml" }, "…");
  const details = el("details", {}, el("summary", {}, "Stored definition (YAML)"), yaml);
  details.addEventListener("toggle", async () => {
    if (!details.open || yaml.dataset.loaded) return;
    const r = await api(`/studies/${studyId}/definition.yaml`);
    yaml.textContent = await r.text();
    yaml.dataset.loaded = "1";
  });
  fill($("#definition"), 
    design.description ? el("p", {}, design.description) : null,
    el(
      "p",
      {},
      `Design: ${d.type}` + (d.samples ? `, ${d.samples} samples (seed ${d.seed})` : "") + `; ${design.n_cases} cases.`
    ),
    design.parameters.length
      ? el(
          "table",
          { id: "parameters" },
          el("thead", {}, el("tr", {}, ["Parameter", "Path", "Values as written", "Scale", "Unit"].map((h) => el("th", {}, h)))),
          el("tbody", {}, rows)
        )
      : el("p", { class: "muted" }, "No varied parameter: one case."),
    details
  );
}

let modelDrawn = 0; // the latest drawing of the model card: an older one still waiting adds nothing

async function renderModel() {
  const drawing = ++modelDrawn;
  const s = study;
  const facts = el(
    "dl",
    { class: "facts" },
    el("dt", {}, "fidelity"),
    el("dd", {}, s.fidelity || "–"),
    el("dt", {}, "integrator"),
    el("dd", {}, s.integrator || "–"),
    el("dt", {}, "time step"),
    el("dd", {}, s.dt ? `${fmt(s.dt * 1e3)} ms` : "–")
  );
  fill($("#model"), facts);
  if (s.status !== "done") return;
  try {
    const e = await apiJson(`/studies/${studyId}/error-estimate`);
    if (drawing !== modelDrawn) return;
    const names = Object.keys(e.outputs);
    if (!names.length) {
      $("#model").appendChild(el("p", { class: "muted" }, "This study carries no error estimate."));
      return;
    }
    $("#model").appendChild(
      el(
        "table",
        { id: "error-estimate" },
        el("thead", {}, el("tr", {}, el("th", {}, "output"), el("th", { class: "num" }, "largest error"), el("th", {}, "worst case"))),
        el(
          "tbody",
          {},
          names.map((n) => {
            const o = e.outputs[n];
            const v = o.value === null ? "–" : o.units === "1" ? `${fmt(100 * o.value, 3)} %` : `${fmt(o.value, 3)} ${o.units}`;
            return el("tr", { title: o.meaning }, el("td", {}, n), el("td", { class: "num" }, v), el("td", {}, o.worst_case ?? "–"));
          })
        )
      ),
      el("p", { class: "muted" }, `Measured on ${e.cases.length} sampled cases against the reference level (${e.method || "–"}).`)
    );
  } catch (err) {
    if (drawing === modelDrawn) $("#model").appendChild(el("p", { class: "error" }, err.message));
  }
}

// -------------------------------------------------------------------------------------------- sweep
function fillSelect(select, names, chosen, blank) {
  fill(select, 
    blank ? el("option", { value: "" }, blank) : null,
    names.map((n) => el("option", { value: n, selected: n === chosen }, n))
  );
}

async function loadSweep() {
  const limit = Math.min(Math.max(study.progress.total, 1), PLOT_ROWS);
  table = await apiJson(`/studies/${studyId}/cases?limit=${limit}`);
  const numeric = table.columns.filter((c) => table.units[c] !== "" && c !== "case");
  const params = design.parameters.map((p) => p.name);
  const outputs = numeric.filter((c) => !params.includes(c));
  const x0 = (design.parameters.find((p) => !p.categorical) || design.parameters[0] || { name: "case" }).name;
  const y0 = outputs.includes("peak_displacement_y") ? "peak_displacement_y" : outputs[0];
  const c0 = params.includes("isolator_type") && x0 !== "isolator_type" ? "isolator_type" : "";
  fillSelect($("#x"), [...params, ...table.columns.filter((c) => !params.includes(c))], x0);
  fillSelect($("#y"), [...outputs, ...params.filter((p) => numeric.includes(p))], y0);
  fillSelect($("#colour"), [...params, ...outputs, "status"].filter((c) => table.columns.includes(c)), c0, "(none)");
  drawSweep();
}

function column(name) {
  const { factor } = columnUnit(name);
  return table.rows.map((r) => (typeof r[name] === "number" ? r[name] * factor : r[name]));
}

function drawSweep() {
  const x = $("#x").value;
  const y = $("#y").value;
  const c = $("#colour").value;
  const xs = column(x);
  const ys = column(y);
  const cases = table.rows.map((r) => r.case);
  const isParam = design.parameters.some((p) => p.name === x);
  const mode = isParam && design.design.type === "grid" ? "lines+markers" : "markers";
  let traces;
  const categorical = c && table.units[c] === "";
  if (!c || categorical) {
    const groups = new Map();
    table.rows.forEach((r, i) => {
      const key = c ? String(r[c]) : y;
      if (!groups.has(key)) groups.set(key, []);
      groups.get(key).push(i);
    });
    traces = [...groups.entries()].map(([key, idx], k) => {
      if (mode !== "markers") idx.sort((a, b) => (xs[a] > xs[b] ? 1 : xs[a] < xs[b] ? -1 : 0));
      return {
        type: "scatter",
        mode,
        name: key,
        x: idx.map((i) => xs[i]),
        y: idx.map((i) => ys[i]),
        customdata: idx.map((i) => cases[i]),
        marker: { color: PALETTE[k % PALETTE.length], size: 7 },
        hovertemplate: "case %{customdata}<br>%{x}, %{y}<extra>%{fullData.name}</extra>",
      };
    });
  } else {
    traces = [
      {
        type: "scatter",
        mode: "markers",
        x: xs,
        y: ys,
        customdata: cases,
        marker: { color: column(c), colorscale: "Viridis", size: 8, colorbar: { title: { text: label(c) } } },
        hovertemplate: "case %{customdata}<br>%{x}, %{y}<extra></extra>",
      },
    ];
  }
  const layout = {
    margin: { t: 20, r: 20, b: 60, l: 70 },
    xaxis: { title: { text: label(x) }, type: columnUnit(x).log ? "log" : undefined },
    yaxis: { title: { text: label(y) }, type: columnUnit(y).log ? "log" : undefined },
    legend: { title: { text: c || "" } },
    height: 440,
  };
  const node = $("#sweep");
  if (!node.classList.contains("js-plotly-plot")) fill(node);
  Plotly.react(node, traces, layout, PLOT_CONFIG);
  if (!node.dataset.clicks) {
    node.dataset.clicks = "1";
    node.on("plotly_click", (ev) => {
      const p = ev.points && ev.points[0];
      if (p && p.customdata !== undefined) location.href = `/ui/studies/${studyId}/cases/${p.customdata}`;
    });
  }
}

// -------------------------------------------------------------------------------------------- cases
function queryString(format, limit) {
  const q = new URLSearchParams({ limit: String(limit), format });
  if ($("#filter").value.trim()) q.set("filter", $("#filter").value.trim());
  if ($("#sort").value.trim()) q.set("sort", $("#sort").value.trim());
  return q.toString();
}

async function loadCases() {
  fill($("#query-error"));
  let page;
  try {
    page = await apiJson(`/studies/${studyId}/cases?${queryString("json", TABLE_ROWS)}`);
  } catch (err) {
    showError("#query-error", err);
    return;
  }
  $("#matched").textContent = `${page.n_matched} of ${page.n_cases} cases match` + (page.n_matched > TABLE_ROWS ? ` (first ${TABLE_ROWS} shown)` : "");
  const units = {};
  for (const col of page.columns) {
    const p = design.parameters.find((q) => q.name === col);
    units[col] = p && !p.categorical ? [p.display_unit, 1 / p.display_scale] : displayUnit(page.units[col]);
  }
  const head = el("tr", {}, page.columns.map((col) => el("th", { class: "num", title: (page.long_names || {})[col] || null }, units[col][0] ? `${col} [${units[col][0]}]` : col)));
  const body = page.rows.map((r) =>
    el(
      "tr",
      {},
      page.columns.map((col) => {
        const v = r[col];
        if (col === "case") return el("td", { class: "num" }, el("a", { href: `/ui/studies/${studyId}/cases/${v}` }, String(v)));
        const shown = typeof v === "number" ? fmt(v * units[col][1]) : fmt(v);
        return el("td", { class: typeof v === "number" ? "num" : "" }, shown);
      })
    )
  );
  fill($("#cases"), el("table", { id: "case-table" }, el("thead", {}, head), el("tbody", {}, body)));
}

// ------------------------------------------------------------------------------------------- answer
async function loadAnswer() {
  const node = $("#answer");
  try {
    const answer = await apiJson(`/studies/${studyId}/answer`);
    if (answer.optimisation) renderOptimisation(node, answer, design);
    else if (answer.criteria) renderStudyCriteria(node, answer);
    else fill(node, el("p", { class: "muted" }, "This study has no criteria or objective: its answer is the sweep and the case table below."));
    const best = answer.optimisation ? answer.optimisation.best_case : answer.criteria && answer.criteria.best_case ? answer.criteria.best_case.case : null;
    loadFloor(best === null || best === undefined ? 0 : best);
  } catch (err) {
    showError(node, err);
  }
  for (const id of ["#report", "#report-download"]) $(id).disabled = false;
}

async function openReport() {
  const tab = window.open("", "_blank"); // opened while the click counts, filled when the report arrives
  $("#report-state").textContent = "Writing the report (it recomputes one case)…";
  try {
    const response = await api(`/studies/${studyId}/report.html`);
    if (!response.ok) throw new ApiError(response.status, await response.json().catch(() => null));
    const url = URL.createObjectURL(new Blob([await response.text()], { type: "text/html" }));
    if (tab) tab.location.href = url;
    else location.href = url;
    $("#report-state").textContent = "";
  } catch (err) {
    if (tab) tab.close();
    showError("#report-state", err);
  }
}

// ---------------------------------------------------------------------------------------------- floor
// The study stands on a floor spectrum: each point's band velocity of one case (the best, at first).
function hasFloorSpectrum() {
  const d = (study && study.definition) || {};
  const floor = d.floor || (d.scene && d.scene.floor);
  return Boolean(floor && floor.spectrum);
}

async function loadFloor(caseNumber) {
  if (!hasFloorSpectrum()) return;
  $("#floor-card").hidden = false;
  const input = el("input", { id: "floor-case", type: "number", min: "0", max: String(Math.max(study.progress.total - 1, 0)), value: String(caseNumber), size: "6" });
  const show = el("button", { type: "button", class: "secondary", id: "floor-show" }, "Show");
  show.addEventListener("click", () => loadFloor(Number(input.value)));
  const chooser = el("label", {}, "case ", input, " ", show);
  fill($("#floor"), el("p", { class: "muted" }, `Computing the spectra of case ${caseNumber}…`));
  try {
    renderFloorSpectra($("#floor"), await apiJson(`/studies/${studyId}/cases/${caseNumber}/floor`), chooser);
  } catch (err) {
    fill($("#floor"), el("div", { class: "controls" }, chooser), el("p", { class: "error" }, String(err.message || err)));
  }
}

const SENSITIVITY_DESIGNS = ["saltelli", "lhs", "sobol", "random"];

// The outputs offered for sensitivity indices: the c.g.'s peaks, settling, and each point's peaks.
function sensitivityOutputs() {
  const fixed = ["peak_displacement.y", "peak_displacement.x", "peak_displacement.z", "peak_rotation.rx", "settling_time", "natural_frequency.1", "min_isolator_load"];
  const points = (table ? table.columns : [])
    .map((c) => c.match(/^peak_point_displacement_(.+)_([xyz])$/))
    .filter(Boolean)
    .map((m) => `peak_point_displacement.${m[1]}.${m[2]}`);
  return [...points, ...fixed];
}

async function drawSensitivityOf(output) {
  fill($("#sensitivity-notes"));
  try {
    const result = await apiJson(`/studies/${studyId}/sensitivity?output=${encodeURIComponent(output)}`);
    drawSensitivity($("#sensitivity"), result);
    const unit = result.unit && result.unit !== "1" ? ` [${displayUnit(result.unit)[0]}]` : "";
    $("#sensitivity-notes").textContent = `${result.method_name} of ${result.long_name}${unit}, from ${result.n_cases} of ${result.n_total} cases. ${(result.notes || []).join(" ")}`;
  } catch (err) {
    showError("#sensitivity", err);
  }
}

function loadSensitivity() {
  if (!SENSITIVITY_DESIGNS.includes(design.design.type) || !design.parameters.length) return;
  $("#sensitivity-card").hidden = false;
  const outputs = sensitivityOutputs();
  fillSelect($("#sensitivity-output"), outputs, outputs[0]);
  drawSensitivityOf(outputs[0]);
}

// ---------------------------------------------------------------------------------------------- flow
async function loadDone() {
  loadedDone = true;
  renderModel();
  loadAnswer();
  try {
    await loadSweep();
  } catch (err) {
    showError("#sweep", err);
  }
  loadSensitivity();
  await loadCases();
}

async function refresh() {
  try {
    study = await apiJson(`/studies/${studyId}`);
  } catch (err) {
    showError("#error", err);
    return;
  }
  renderStatus();
  if (!design) {
    try {
      design = await apiJson(`/studies/${studyId}/design`);
      renderDefinition();
      renderModel();
    } catch (err) {
      showError("#definition", err);
    }
  }
  if (study.status === "done" && !loadedDone) await loadDone();
  if (study.status === "queued" || study.status === "running") setTimeout(refresh, 1200);
  else if (study.status !== "done") renderModel();
}

header("studies");
for (const id of ["#x", "#y", "#colour"]) $(id).addEventListener("change", drawSweep);
$("#query").addEventListener("submit", (e) => {
  e.preventDefault();
  loadCases();
});
$("#csv").addEventListener("click", () =>
  download(`/studies/${studyId}/cases?${queryString("csv", 100000)}`, `${study ? study.name : "study"}-cases.csv`).catch((err) => showError("#query-error", err))
);
$("#report").addEventListener("click", openReport);
$("#report-download").addEventListener("click", () =>
  download(`/studies/${studyId}/report.html`, `${study ? study.name : "study"}-report.html`).catch((err) => showError("#report-state", err))
);
$("#sensitivity-output").addEventListener("change", () => drawSensitivityOf($("#sensitivity-output").value));
$("#netcdf").addEventListener("click", () =>
  download(`/studies/${studyId}/dataset`, `${study ? study.name : "study"}-${studyId}.nc`).catch((err) => showError("#query-error", err))
);
refresh();
