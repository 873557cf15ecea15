// /ui/calibrate and /ui/calibrations/{id}: start a calibration (a scene, a measurement CSV, the parameters
// to fit) and read its answer: progress, the goodness of fit in words, the fitted values with their
// uncertainty, measured against simulated traces per channel, the calibrated scene.
"use strict";

function calibrationIdFromPath() {
  const m = location.pathname.match(/\/ui\/calibrations\/([0-9a-fA-F]+)$/);
  return m ? m[1] : null;
}

// ------------------------------------------------------------------------------------------ the form
// "path=lower:upper" (units allowed, "@start" optional) -> the request's fit entry
function parseFitLine(line, k) {
  const m = line.match(/^\s*([A-Za-z0-9_.\[\]-]+)\s*=\s*([^:@]+?)\s*:\s*([^:@]+?)\s*(?:@\s*(.+?)\s*)?$/);
  if (!m) throw new Error(`fit line ${k + 1}: write PATH=LOWER:UPPER, e.g. isolators.f_horizontal=1 Hz:6 Hz`);
  const value = (t) => (/^[-+0-9.eE]+$/.test(t) ? Number(t) : t);
  const fit = { path: m[1], lower: value(m[2]), upper: value(m[3]) };
  if (m[4]) fit.start = value(m[4]);
  return fit;
}

function parseNoise(text) {
  const noise = {};
  text.split("\n").map((l) => l.trim()).filter(Boolean).forEach((line, k) => {
    const m = line.match(/^([^=]+?)\s*=\s*(.+)$/);
    if (!m) throw new Error(`noise line ${k + 1}: write CHANNEL=NOISE, e.g. cg.y.displacement=0.01 mm`);
    noise[m[1]] = /^[-+0-9.eE]+$/.test(m[2]) ? Number(m[2]) : m[2];
  });
  return noise;
}

// The scene as data: an example's, or a file's (read by the service: YAML is checked as a study's scene).
async function sceneData() {
  const file = $("#scene-file").files[0];
  if (!file) {
    const name = $("#scene-example").value;
    if (!name) throw new Error("choose an example scene or a scene file");
    return (await apiJson(`/scenes/examples/${encodeURIComponent(name)}`)).scene;
  }
  const text = await file.text();
  const body = text.trim().startsWith("{") ? `scene: ${text.replace(/\n/g, " ")}` : "scene:\n" + text.split("\n").map((l) => `  ${l}`).join("\n");
  const checked = await postJson("/studies/validate", { text: `name: calibration\n${body}\n` });
  return checked.definition.scene;
}

async function submit(event) {
  event.preventDefault();
  const state = $("#form-state");
  $("#calibrate").disabled = true;
  state.textContent = "Reading the scene…";
  try {
    const scene = await sceneData();
    const csv = await $("#measurement-file").files[0].text();
    const fit = $("#fit").value.split("\n").map((l) => l.trim()).filter(Boolean).map(parseFitLine);
    const body = { scene, measurement: { csv }, fit, starts: Number($("#starts").value) || 1 };
    const noise = parseNoise($("#noise").value);
    if (Object.keys(noise).length) body.noise = noise;
    state.textContent = "Submitting…";
    const job = await postJson("/calibrations", body);
    location.href = `/ui/calibrations/${job.id}`;
  } catch (err) {
    showError(state, err);
  } finally {
    $("#calibrate").disabled = false;
  }
}

async function loadExamples() {
  const names = (await apiJson("/scenes/examples")).names;
  $("#scene-example").append(...names.map((n) => el("option", { value: n }, n)));
}

// ------------------------------------------------------------------------------------------ the answer
// A fitted value in a unit that reads well: a damping ratio in %, a length in mm, a time in ms.
function fittedText(value, unit, path) {
  if (value === null || value === undefined) return "–";
  if ((unit === "1" || unit === "") && /zeta|damping/.test(path)) return `${fmt(100 * value, 4)} %`;
  return quantityText(value, unit);
}

function sigmaText(p) {
  if (!p.determined) return el("span", { class: "fail" }, `not determined: ${p.reason || "the measurement does not fix it"}`);
  if (p.sigma === null || p.sigma === undefined) return "–";
  const share = p.value ? ` (${fmt((100 * p.sigma) / Math.abs(p.value), 2)} %)` : "";
  return `± ${fittedText(p.sigma, p.unit, p.path)}${share}`;
}

function fittedTable(result) {
  const rows = [...result.parameters, { ...result.time_offset, path: result.time_offset.path || "time offset" }].map((p) =>
    el(
      "tr",
      { "data-path": p.path },
      el("td", { title: p.name || p.path }, p.path),
      el("td", { class: "num" }, fittedText(p.start, p.unit, p.path)),
      el("td", { class: "num value" }, fittedText(p.value, p.unit, p.path)),
      el("td", { class: "sigma" }, sigmaText(p)),
      el("td", {}, `${fittedText(p.lower, p.unit, p.path)} … ${fittedText(p.upper, p.unit, p.path)}`)
    )
  );
  return el(
    "table",
    { id: "fitted-table" },
    el("thead", {}, el("tr", {}, ["parameter", "scene's value", "fitted", "uncertainty (1 σ)", "bounds"].map((h) => el("th", {}, h)))),
    el("tbody", {}, rows)
  );
}

function verdictNode(result) {
  const g = result.goodness_of_fit || {};
  const ok = g.consistent;
  const channels = (g.channels || []).map((c) =>
    el(
      "tr",
      {},
      el("td", {}, c.name),
      el("td", { class: "num" }, fmt(c.chi_square, 4)),
      el("td", { class: "num" }, fmt(c.dof, 4)),
      el("td", { class: "num" }, fmt(c.reduced_chi_square, 3)),
      el("td", {}, `${fmt(c.expected_range[0], 3)} … ${fmt(c.expected_range[1], 3)}`),
      el("td", {}, c.noise === "stated" ? "stated" : "estimated from the record"),
      el("td", {}, c.consistent ? el("span", { class: "pass" }, "within the noise") : el("span", { class: "fail" }, "beyond the noise"))
    )
  );
  const starts = result.starts && result.starts.count > 1 ? el("p", {}, `${result.starts.count} starts, ${result.starts.agreeing} ending within 3 σ of the best (start ${result.starts.best + 1}).`) : null;
  return [
    el("div", { class: `answer ${ok ? "ok" : "warn"}`, id: "fit-verdict" }, el("strong", {}, ok ? "The fit matches the measurement within its noise. " : "The fit does not match the measurement within its noise. "), `In words: ${g.verdict || result.message}.`),
    el(
      "table",
      { id: "chi-square" },
      el("thead", {}, el("tr", {}, ["channel", "χ²", "degrees of freedom", "χ²/dof", "expected χ²/dof (95 %)", "noise", ""].map((h) => el("th", {}, h)))),
      el("tbody", {}, channels)
    ),
    starts,
  ];
}

function drawTraces(node, traces) {
  const n = traces.channels.length;
  const data = [];
  const layout = {
    height: 260 * n + 80,
    grid: { rows: n, columns: 1, pattern: "independent", roworder: "top to bottom" },
    margin: { t: 30, r: 20, b: 50, l: 80 },
    legend: { orientation: "h", y: 1.06, x: 0 },
  };
  traces.channels.forEach((ch, i) => {
    const ax = i === 0 ? "" : String(i + 1);
    const scale = (vs) => vs.map((v) => (v === null ? null : v / (ch.factor || 1)));
    const common = { type: "scatter", mode: "lines", x: traces.time, xaxis: `x${ax}`, yaxis: `y${ax}` };
    data.push({ ...common, name: "measured", legendgroup: "m", showlegend: i === 0, y: scale(ch.measured), line: { color: "#9a9a9a", width: 3 } });
    data.push({ ...common, name: "scene as given", legendgroup: "b", showlegend: i === 0, y: scale(ch.before), line: { color: "#1f77b4", width: 1.2, dash: "dash" } });
    data.push({ ...common, name: "calibrated", legendgroup: "a", showlegend: i === 0, y: scale(ch.after), line: { color: "#d62728", width: 1.5 } });
    layout[`yaxis${ax}`] = { title: { text: ch.unit ? `${ch.name} [${ch.unit}]` : ch.name, font: { size: 11 } } };
    layout[`xaxis${ax}`] = { title: i === n - 1 ? { text: "measurement time [s]" } : undefined, matches: i ? "x" : undefined };
  });
  fill(node);
  Plotly.newPlot(node, data, layout, PLOT_CONFIG);
}

function renderResult(result) {
  for (const id of ["#verdict-card", "#fitted-card", "#traces-card", "#scene-card"]) $(id).hidden = false;
  fill($("#verdict"), verdictNode(result));
  fill($("#fitted"), fittedTable(result), el("p", { class: "muted" }, "The uncertainty is one standard deviation, from the fit's Jacobian and the misfit (inflated where the residuals are correlated)."));
  if (result.traces) {
    const plot = el("div", { id: "traces-plot", class: "plot" });
    fill($("#traces"), plot, el("p", { class: "muted" }, `Acceleration channels as the fit saw them (detrended and band-passed ${fmt(result.highpass, 3)} … ${fmt(result.lowpass, 3)} Hz); every ${result.traces.every === 1 ? "" : `${result.traces.every}th `}sample shown.`));
    drawTraces(plot, result.traces);
  } else {
    fill($("#traces"), el("p", { class: "muted" }, "This calibration stored no traces."));
  }
  $("#scene-yaml").textContent = result.scene_yaml;
}

let lastStatus = null;

async function refresh(id) {
  let job;
  try {
    job = await apiJson(`/calibrations/${id}`);
  } catch (err) {
    showError("#job", err);
    return;
  }
  const pct = Math.round(100 * job.progress.fraction);
  fill(
    $("#job"),
    el("p", {}, "Status: ", statusBadge(job.status), ` (${pct} %, ${job.progress.engine_calls} engine batches, ${job.progress.cases} cases; estimated ${seconds(job.estimate.seconds)} of engine time)`),
    job.error ? el("p", { class: "error", id: "job-error" }, job.error) : null
  );
  if (job.status === "done" && lastStatus !== "done") renderResult(job.result);
  lastStatus = job.status;
  if (job.status === "queued" || job.status === "running") setTimeout(() => refresh(id), 1000);
}

header("calibrate");
const jobId = calibrationIdFromPath();
if (jobId) {
  $("#title").textContent = "Calibration";
  $("#job-card").hidden = false;
  $("#scene-download").addEventListener("click", () => {
    const url = URL.createObjectURL(new Blob([$("#scene-yaml").textContent], { type: "application/yaml" }));
    const a = el("a", { href: url, download: `calibrated-scene-${jobId}.yaml` });
    document.body.appendChild(a);
    a.click();
    a.remove();
    setTimeout(() => URL.revokeObjectURL(url), 10000);
  });
  refresh(jobId);
} else {
  $("#form-card").hidden = false;
  $("#calibrate-form").addEventListener("submit", submit);
  loadExamples().catch((err) => showError("#form-state", err));
}
