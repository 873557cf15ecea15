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
        marker: { color: TYPE_COLOURS[t] || PALETTE[types.indexOf(t) % PALETTE.length] },
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

// ------------------------------------------------------------------------------- catalogue products
// The catalogue the user chose: null (the generic types), a shipped one's name, or an uploaded file read
// and checked by the service (POST /catalogues/read), which answers the catalogue as a comparison takes it.
async function catalogueChoice() {
  const choice = $("#catalogue").value;
  if (!choice) return null;
  if (choice.startsWith("shipped:")) return choice.slice("shipped:".length);
  const file = $("#catalogue-file").files[0];
  if (!file) throw new Error("Choose a catalogue file (YAML or CSV) first.");
  const ending = file.name.toLowerCase().split(".").pop();
  const format = ending === "csv" ? "csv" : ending === "json" ? "json" : "yaml";
  const name = file.name.replace(/\.[^.]*$/, "") || "catalogue";
  const read = await postJson("/catalogues/read", { text: await file.text(), format, name });
  $("#catalogue-state").textContent = `${file.name}: ${read.products.length} products.`;
  return read.catalogue;
}

function perCorner() {
  const text = $("#per-corner").value.trim();
  if (!text) return null;
  const counts = text.split(/[\s,]+/).filter(Boolean).map(Number);
  if (counts.some((n) => !Number.isInteger(n) || n < 1)) throw new Error(`Isolators a mount may take: whole numbers from 1, comma-separated (got "${text}").`);
  return counts;
}

function showCatalogueControls() {
  const choice = $("#catalogue").value;
  $("#catalogue-file").hidden = choice !== "file";
  $("#per-corner-field").hidden = !choice;
  $("#tune").disabled = Boolean(choice); // a product's figures are its datasheet's
  $("#catalogue-state").textContent = "";
}

// Why a compared product misses the criteria, each criterion in words with its margin.
function failedInWords(answer, row) {
  const missed = (answer.requirements || []).filter((r) => typeof row[`margin_${r.name}`] === "number" && row[`margin_${r.name}`] < 0);
  if (!missed.length) return row.status && row.status !== "ok" ? `its case did not end ok (${row.status})` : "misses the criteria";
  return "fails " + missed.map((r) => `${r.description || r.name} (${percentText(row[`margin_${r.name}`])})`).join(", ");
}

// Each product of the catalogue, cheapest first: count, cost, load margin, pressure, stroke used, criteria
// met, and the verdict in words; the recommended one marked, and every cheaper one with why it is not.
function productLines(answer) {
  const block = answer.catalogue;
  const reqs = answer.requirements || [];
  const pick = (answer.recommendation || {}).product || null;
  const lines = block.products.map((p) => {
    const row = answer.rows[p.product] || null;
    const margins = p.load_margin.filter((m) => typeof m === "number");
    const pressures = row ? p.pressure.filter((x) => typeof x === "number") : [];
    const deflection = row ? row.peak_isolator_deflection_z : null;
    const met = row ? reqs.filter((r) => row[`margin_${r.name}`] >= 0).length : null;
    const feasible = Boolean(row) && (reqs.length ? Boolean(row.meets_criteria) : row.status === "ok");
    let why = null;
    if (!row) why = `does not carry the loads: ${p.reason}`;
    else if (!feasible) why = failedInWords(answer, row);
    return { p, row, margins, pressures, deflection, met, feasible, why, picked: p.product === pick };
  });
  const rank = (l) => [l.row ? 0 : 1, l.p.cost === null || l.p.cost === undefined ? 1 : 0, l.p.cost || 0];
  lines.sort((a, b) => {
    const [x, y] = [rank(a), rank(b)];
    return x[0] - y[0] || x[1] - y[1] || x[2] - y[2];
  });
  return lines;
}

function renderProducts(answer) {
  const card = $("#products-card");
  if (!answer.catalogue) {
    card.hidden = true;
    return;
  }
  card.hidden = false;
  const block = answer.catalogue;
  const reqs = answer.requirements || [];
  const lines = productLines(answer);
  const range = (xs, f, digits) => (xs.length ? (Math.min(...xs) === Math.max(...xs) ? fmt(Math.min(...xs) * f, digits) : `${fmt(Math.min(...xs) * f, digits)}–${fmt(Math.max(...xs) * f, digits)}`) : "–");
  const head = el(
    "tr",
    {},
    ["product", "type", "isolators", `cost [${block.currency}]`, "smallest load margin [%]", "pressure [bar]", "stroke used [%]", "criteria met", "verdict"].map((h, i) =>
      el("th", { class: i >= 2 && i <= 7 ? "num" : null }, h)
    )
  );
  const body = lines.map((l) => {
    const verdictText = l.picked ? "recommended" : l.feasible ? (reqs.length ? "meets every criterion" : "carries the loads") : l.why;
    const strokeUsed = l.deflection !== null && l.deflection !== undefined && l.p.stroke ? fmt((100 * l.deflection) / l.p.stroke, 3) : "–";
    return el(
      "tr",
      { "data-product": l.p.product, class: l.picked ? "recommended best" : l.feasible ? null : "rejected" },
      el("td", { title: l.p.label }, l.picked ? el("strong", {}, `★ ${l.p.product}`) : l.p.product),
      el("td", {}, l.p.type),
      el("td", { class: "num" }, l.row ? `${l.p.counts.reduce((a, b) => a + b, 0)} (${l.p.counts.join("/")})` : "–"),
      el("td", { class: "num" }, l.p.cost === null || l.p.cost === undefined ? (l.p.unit_price == null ? "no price" : `${fmt(l.p.unit_price)} each`) : l.p.cost.toLocaleString("en")),
      el("td", { class: "num" }, range(l.margins, 100, 3)),
      el("td", { class: "num" }, range(l.pressures, 1e-5, 3)),
      el("td", { class: "num" }, strokeUsed),
      el("td", { class: "num" }, l.met === null || !reqs.length ? "–" : `${l.met} of ${reqs.length}`),
      el("td", { class: l.picked || l.feasible ? "pass" : "fail" }, verdictText)
    );
  });
  const at = lines.findIndex((l) => l.picked);
  const cheaper = (at >= 0 ? lines.slice(0, at) : lines).filter((l) => !l.feasible);
  const why = cheaper.length
    ? el(
        "div",
        { id: "rejected" },
        el("h3", {}, at >= 0 ? "Cheaper products, and why not" : "Why no product is recommended"),
        el("ul", {}, cheaper.map((l) => el("li", { "data-product": l.p.product }, el("strong", {}, `${l.p.product}: `), l.why)))
      )
    : null;
  fill(
    $("#products"),
    el("div", { class: "table-wrap" }, el("table", { id: "products-table" }, el("thead", {}, head), el("tbody", {}, body))),
    why,
    el("p", { class: "muted" }, `Catalogue ${block.name}; each product at the fewest isolators per mount (of ${block.per_corner.join(" or ")}) that carry the static loads within a ${Math.round(100 * block.margin)} % load margin; prices in ${block.currency}.`)
  );
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
    const catalogue = await catalogueChoice();
    const tune = !catalogue && $("#tune").checked;
    $("#state").textContent = tune ? "Tuning each type, then running… (about a minute)" : catalogue ? "Running each product that carries the loads…" : "Running…";
    const request = catalogue ? { scene, isolator_types: types, simulation, catalogue, per_corner: perCorner() } : { scene, isolator_types: types, simulation, tune };
    const answer = await postJson("/comparisons", request);
    renderComparisonAnswer($("#answer"), answer);
    renderProducts(answer);
    renderBars(answer);
    renderTable(answer);
    $("#state").textContent = "";
    if (catalogue) $("#floor-card").hidden = true; // the floor view draws the generic types
    else drawFloor(scene, types, simulation).catch((err) => showError("#floor", err));
  } catch (err) {
    showError("#state", err);
  } finally {
    $("#run").disabled = false;
  }
}

header("compare");
$("#run").addEventListener("click", run);
$("#catalogue").addEventListener("change", showCatalogueControls);
loadSources().catch((err) => showError("#state", err));
