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

function label(name) {
  const u = columnUnit(name).unit;
  return u ? `${name} [${u}]` : name;
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

async function renderModel() {
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
    $("#model").appendChild(el("p", { class: "error" }, err.message));
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
  const head = el("tr", {}, page.columns.map((col) => el("th", { class: "num" }, units[col][0] ? `${col} [${units[col][0]}]` : col)));
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

// ---------------------------------------------------------------------------------------------- flow
async function loadDone() {
  loadedDone = true;
  renderModel();
  try {
    await loadSweep();
  } catch (err) {
    showError("#sweep", err);
  }
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
$("#netcdf").addEventListener("click", () =>
  download(`/studies/${studyId}/dataset`, `${study ? study.name : "study"}-${studyId}.nc`).catch((err) => showError("#query-error", err))
);
refresh();
