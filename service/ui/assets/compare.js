// /ui/compare: one scene under each isolator type (POST /comparisons), side by side on the same axes.
"use strict";

const TYPE_COLOURS = { active: "#1f77b4", air: "#ff7f0e", elastomer: "#2ca02c" };
const FAMILIES = [
  ["peak_displacement_", "peak c.g. displacement"],
  ["peak_rotation_", "peak rotation"],
  ["peak_isolator_force_", "peak dynamic isolator force"],
  ["peak_point_displacement_", "peak point displacement"],
  ["natural_frequency_", "natural frequencies"],
  ["settling_time", "settling time"],
  ["min_isolator_load_min", "smallest isolator load"],
];

async function loadSources() {
  const select = $("#source");
  // a scene handed over by the scene builder (/ui/scene: Compare types), kept in the tab's sessionStorage
  if (new URLSearchParams(location.search).get("from") === "draft" && sessionStorage.getItem("isolab-draft-scene")) {
    select.appendChild(el("option", { value: "draft:scene", selected: true }, "the scene from the builder"));
  }
  const examples = await apiJson("/examples");
  select.appendChild(el("optgroup", { label: "Examples" }, examples.names.map((n) => el("option", { value: `example:${n}` }, n))));
  const stored = await apiJson("/studies?status=done&limit=100");
  if (stored.items.length) {
    select.appendChild(el("optgroup", { label: "Done studies" }, stored.items.map((s) => el("option", { value: `study:${s.id}` }, `${s.name} (${when(s.created)})`))));
  }
}

async function sceneOf(source) {
  const [kind, key] = source.split(/:(.*)/s);
  if (kind === "draft") return { scene: JSON.parse(sessionStorage.getItem("isolab-draft-scene")), simulation: null };
  let definition;
  if (kind === "example") {
    const example = await apiJson(`/examples/${encodeURIComponent(key)}`);
    definition = (await postJson("/studies/validate", { text: example.text })).definition;
  } else {
    definition = (await apiJson(`/studies/${encodeURIComponent(key)}`)).definition;
  }
  // a study's own floor and criteria replace its scene's (as when the study runs)
  const scene = { ...definition.scene };
  for (const key of ["floor", "criteria"]) if (definition[key]) scene[key] = definition[key];
  return { scene, simulation: definition.simulation || null };
}

function renderTable(answer) {
  const types = answer.isolator_types;
  const rows = answer.columns.map((c) => {
    const [unit, factor] = displayUnit(answer.units[c]);
    return el(
      "tr",
      {},
      el("td", {}, unit ? `${c} [${unit}]` : c),
      types.map((t) => {
        const v = answer.rows[t][c];
        return el("td", { class: "num" + (answer.best[c] === t ? " best" : "") }, typeof v === "number" ? fmt(v * factor) : fmt(v));
      }),
      el("td", { class: "muted" }, answer.criteria[c] ? `best: ${answer.criteria[c]}` : "")
    );
  });
  // outputs, not criteria: the criteria (their margins and whether all are met) are the answer above
  const outputs = Object.keys(answer.best).filter((c) => !c.startsWith("margin_") && c !== "meets_criteria");
  const tally = {};
  for (const c of outputs) tally[answer.best[c]] = (tally[answer.best[c]] || 0) + 1;
  const summary = Object.entries(tally)
    .sort((a, b) => b[1] - a[1])
    .map(([t, n]) => `${t} has the lowest (or best) value of ${n} of ${outputs.length} outputs`)
    .join("; ");
  fill($("#table"), 
    el("p", {}, summary + "."),
    el(
      "table",
      { id: "comparison-table" },
      el("thead", {}, el("tr", {}, el("th", {}, "output"), types.map((t) => el("th", { class: "num" }, t)), el("th", {}, "criterion"))),
      el("tbody", {}, rows)
    ),
    el("p", { class: "muted" }, `Simulation: ${Object.entries(answer.simulation).map(([k, v]) => `${k} ${fmt(v)}`).join(", ")}. The best value of each row is shaded.`)
  );
}

function renderBars(answer) {
  const types = answer.isolator_types;
  const families = FAMILIES.map(([prefix, title]) => [title, answer.columns.filter((c) => c.startsWith(prefix))]).filter(([, cols]) => cols.length);
  const n = families.length;
  const cols = 2;
  const rows = Math.ceil(n / cols);
  const traces = [];
  const layout = {
    height: 300 * rows + 60,
    grid: { rows, columns: cols, pattern: "independent", roworder: "top to bottom" },
    barmode: "group",
    margin: { t: 40, r: 20, b: 60, l: 70 },
    annotations: [],
    legend: { orientation: "h", y: 1.04, x: 0 },
  };
  families.forEach(([title, columns], i) => {
    const ax = i === 0 ? "" : String(i + 1);
    const [unit, factor] = displayUnit(answer.units[columns[0]]);
    for (const t of types) {
      traces.push({
        type: "bar",
        name: t,
        legendgroup: t,
        showlegend: i === 0,
        marker: { color: TYPE_COLOURS[t] || "#888" },
        x: columns.map((c) => c.replace(/^(peak_displacement|peak_rotation|peak_isolator_force|peak_point_displacement|natural_frequency)_/, "")),
        y: columns.map((c) => (typeof answer.rows[t][c] === "number" ? answer.rows[t][c] * factor : null)),
        xaxis: `x${ax}`,
        yaxis: `y${ax}`,
      });
    }
    layout[`yaxis${ax}`] = { title: { text: `${title}${unit ? ` [${unit}]` : ""}`, font: { size: 11 } } };
    layout[`xaxis${ax}`] = { type: "category" };
  });
  const node = $("#bars");
  fill(node);
  Plotly.newPlot(node, traces, layout, PLOT_CONFIG);
}

// The floor-induced velocity of every point per type against the VC curves, for a scene standing on a
// floor spectrum (/comparisons/floor), with the service's figure of one point as a PNG beside it.
async function drawFloor(scene, types, simulation) {
  const card = $("#floor-card");
  const spectrum = scene.floor && scene.floor.spectrum;
  const points = Object.keys(scene.points || {});
  if (!spectrum || !points.length) {
    card.hidden = true;
    return;
  }
  card.hidden = false;
  fill($("#floor"), el("p", { class: "muted" }, "Computing the spectra at each point…"));
  const spectra = await postJson("/comparisons/floor", { scene, isolator_types: types, simulation });
  const judged = Object.keys(spectra.criteria);
  const point = judged.length ? judged[0] : spectra.points[0];
  const png = el("button", { type: "button", class: "secondary", id: "floor-png" }, `Figure of ${point} (PNG)`);
  png.addEventListener("click", () => downloadFloorPng(scene, types, simulation, point).catch((err) => showError("#state", err)));
  renderFloorSpectra($("#floor"), spectra, png);
}

async function downloadFloorPng(scene, types, simulation, point) {
  const response = await api("/comparisons/floor.png", {
    method: "POST",
    headers: { "content-type": "application/json" },
    body: JSON.stringify({ scene, isolator_types: types, simulation, point }),
  });
  if (!response.ok) throw new ApiError(response.status, await response.json().catch(() => null));
  const url = URL.createObjectURL(await response.blob());
  const a = el("a", { href: url, download: `floor-${point}.png` });
  document.body.appendChild(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 10000);
}

async function run() {
  const types = [...document.querySelectorAll("input[name=type]:checked")].map((c) => c.value);
  if (!types.length) {
    $("#state").textContent = "Choose at least one isolator type.";
    return;
  }
  $("#run").disabled = true;
  $("#state").textContent = "Running…";
  try {
    const { scene, simulation } = await sceneOf($("#source").value);
    const tune = $("#tune").checked;
    $("#state").textContent = tune ? "Tuning each type, then running… (about a minute)" : "Running…";
    const answer = await postJson("/comparisons", { scene, isolator_types: types, simulation, tune });
    renderComparisonAnswer($("#answer"), answer);
    renderBars(answer);
    renderTable(answer);
    $("#state").textContent = "";
    drawFloor(scene, types, simulation).catch((err) => showError("#floor", err));
  } catch (err) {
    showError("#state", err);
  } finally {
    $("#run").disabled = false;
  }
}

header("compare");
$("#run").addEventListener("click", run);
loadSources().catch((err) => showError("#state", err));
