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
  const examples = await apiJson("/examples");
  select.appendChild(el("optgroup", { label: "Examples" }, examples.names.map((n) => el("option", { value: `example:${n}` }, n))));
  const stored = await apiJson("/studies?status=done&limit=100");
  if (stored.items.length) {
    select.appendChild(el("optgroup", { label: "Done studies" }, stored.items.map((s) => el("option", { value: `study:${s.id}` }, `${s.name} (${when(s.created)})`))));
  }
}

async function sceneOf(source) {
  const [kind, key] = source.split(/:(.*)/s);
  let definition;
  if (kind === "example") {
    const example = await apiJson(`/examples/${encodeURIComponent(key)}`);
    definition = (await postJson("/studies/validate", { text: example.text })).definition;
  } else {
    definition = (await apiJson(`/studies/${encodeURIComponent(key)}`)).definition;
  }
  return { scene: definition.scene, simulation: definition.simulation || null };
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
  const tally = {};
  for (const t of Object.values(answer.best)) tally[t] = (tally[t] || 0) + 1;
  const summary = Object.entries(tally)
    .sort((a, b) => b[1] - a[1])
    .map(([t, n]) => `${t} is best on ${n} of ${Object.keys(answer.best).length} criteria`)
    .join("; ");
  fill($("#table"), 
    answer.recommendation ? el("p", { class: "ok" }, `Recommendation: ${typeof answer.recommendation === "string" ? answer.recommendation : JSON.stringify(answer.recommendation)}`) : null,
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
    const answer = await postJson("/comparisons", { scene, isolator_types: types, simulation });
    renderBars(answer);
    renderTable(answer);
    $("#state").textContent = "";
  } catch (err) {
    showError("#state", err);
  } finally {
    $("#run").disabled = false;
  }
}

header("compare");
$("#run").addEventListener("click", run);
loadSources().catch((err) => showError("#state", err));
