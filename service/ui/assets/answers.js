// isolab web page: the answers as an engineer reads them. A comparison's recommendation and criteria
// (limit, value, margin in %, pass or fail per type, the tuned values), an optimisation's progress, cloud
// and best design, sensitivity indices with their intervals. Every text is built as DOM nodes; fields the
// views do not know are left alone.
"use strict";

// SI unit -> the units a value may be shown in, largest first: [unit, SI per unit]
const READABLE = {
  m: [["m", 1], ["mm", 1e-3], ["µm", 1e-6], ["nm", 1e-9]],
  "m/s": [["m/s", 1], ["mm/s", 1e-3], ["µm/s", 1e-6]],
  N: [["MN", 1e6], ["kN", 1e3], ["N", 1]],
  s: [["s", 1], ["ms", 1e-3]],
  rad: [["rad", 1], ["mrad", 1e-3], ["µrad", 1e-6]],
};

// A value (SI) with a unit that reads well at its magnitude: 0.00567 m -> "5.67 mm".
function quantityText(value, unit) {
  if (value === null || value === undefined || (typeof value === "number" && !isFinite(value))) return "–";
  if (typeof value !== "number") return String(value);
  const choices = READABLE[unit];
  if (!choices) return unit && unit !== "1" ? `${fmt(value)} ${unit}` : fmt(value);
  const a = Math.abs(value);
  const [u, one] = choices.find(([, f]) => a >= f) || choices[choices.length - 1];
  return `${fmt(value / one)} ${u}`;
}

// A fraction as a signed percentage: 0.17 -> "+17.0 %".
function percentText(fraction) {
  if (fraction === null || fraction === undefined || !isFinite(fraction)) return "–";
  const p = 100 * fraction;
  return `${p >= 0 ? "+" : "−"}${Math.abs(p).toFixed(1)} %`;
}

function verdict(margin) {
  if (margin === null || margin === undefined || !isFinite(margin)) return el("span", { class: "fail" }, "not judged");
  return margin >= 0 ? el("span", { class: "pass" }, "pass") : el("span", { class: "fail" }, "fail");
}

// The value a criterion judged, from its margin: limit × (1 − margin); no lift-off: the share of its
// preload the most unloaded mount keeps (the margin itself).
function criterionValue(req, margin) {
  if (margin === null || margin === undefined || !isFinite(margin)) return "–";
  if (req.name === "isolators_no_liftoff") return `${(100 * margin).toFixed(1)} % of preload kept`;
  return quantityText(req.limit * (1 - margin), req.unit);
}

function criterionLimit(req) {
  if (req.name === "isolators_no_liftoff") return "keeps part of its preload";
  return `${req.name.endsWith("_settle") ? "within " : "at most "}${quantityText(req.limit, req.unit)}`;
}

// ------------------------------------------------------------------------------------ comparison
// The recommendation in words: green only when a type meets every criterion.
function recommendationNode(answer) {
  const rec = answer.recommendation || {};
  if (rec.product) {
    return el("div", { class: "answer ok", id: "recommendation", "data-product": rec.product }, el("strong", {}, `Recommended: ${rec.product} (${rec.isolator_type}). `), reasonInWords(rec.reason || "", answer.requirements || []));
  }
  if (rec.isolator_type) {
    return el("div", { class: "answer ok", id: "recommendation" }, el("strong", {}, `Recommended: ${rec.isolator_type} isolators. `), reasonInWords(rec.reason || "", answer.requirements || []));
  }
  const what = answer.catalogue ? "product" : "type";
  const none = (answer.requirements || []).length ? `No ${what} meets every criterion. ` : "No recommendation. ";
  return el("div", { class: "answer warn", id: "recommendation" }, el("strong", {}, none), reasonInWords(rec.reason || "", answer.requirements || []));
}

// The service's reason with each criterion named by its description (``tool_settle`` -> ``tool back
// within 10 um of rest after each move``) and without the opening the heading already says.
function reasonInWords(reason, requirements) {
  let text = reason.replace(/^no (type|product of the catalogue) meets every criterion: /, "");
  const names = [...requirements].sort((a, b) => b.name.length - a.name.length);
  for (const r of names) {
    if (r.description) text = text.replace(new RegExp(`\\b${r.name}\\b`, "g"), r.description);
  }
  return text.charAt(0).toUpperCase() + text.slice(1);
}

// Each type against each criterion: how many it meets, counting the criteria only.
function criteriaTally(answer) {
  const reqs = answer.requirements || [];
  if (!reqs.length) return null;
  return el(
    "p",
    { id: "criteria-tally" },
    answer.isolator_types
      .map((t) => {
        const met = reqs.filter((r) => (answer.rows[t] || {})[`margin_${r.name}`] >= 0).length;
        return `${t} meets ${met} of ${reqs.length} criteria`;
      })
      .join("; ") + "."
  );
}

function criteriaTable(answer) {
  const reqs = answer.requirements || [];
  if (!reqs.length) return el("p", { class: "muted" }, "The scene has no criteria: add a criteria block to get margins and a recommendation.");
  const types = answer.isolator_types;
  const head = el(
    "thead",
    {},
    el("tr", {}, el("th", { rowspan: "2" }, "criterion"), el("th", { rowspan: "2" }, "limit"), types.map((t) => el("th", { colspan: "3", class: "type" }, t))),
    el("tr", {}, types.map(() => [el("th", { class: "num" }, "value"), el("th", { class: "num" }, "margin"), el("th", {}, "")]))
  );
  const body = reqs.map((r) =>
    el(
      "tr",
      { "data-criterion": r.name },
      el("td", { title: r.name }, r.description || r.name),
      el("td", {}, criterionLimit(r)),
      types.map((t) => {
        const m = (answer.rows[t] || {})[`margin_${r.name}`];
        return [el("td", { class: "num" }, criterionValue(r, m)), el("td", { class: "num margin" }, percentText(m)), el("td", {}, verdict(m))];
      })
    )
  );
  const all = el(
    "tr",
    { class: "all" },
    el("td", { colspan: "2" }, el("strong", {}, "every criterion")),
    types.map((t) => {
      const meets = (answer.rows[t] || {}).meets_criteria;
      return el("td", { colspan: "3" }, meets ? el("span", { class: "pass" }, "meets them all") : el("span", { class: "fail" }, "fails"));
    })
  );
  return el("table", { id: "criteria-table" }, head, el("tbody", {}, body, all));
}

const TUNED_NAMES = { f_vertical: "vertical natural frequency", f_horizontal: "horizontal natural frequency", zeta: "damping ratio" };

function tuningTable(answer) {
  if (!answer.tuning) return null;
  const types = Object.keys(answer.tuning);
  const keys = [...new Set(types.flatMap((t) => Object.keys(answer.tuning[t].values || {})))];
  const shown = (k, v, unit) => (unit === "1" || k === "zeta" ? `${fmt(100 * v, 3)} %` : `${fmt(v, 3)} ${unit || ""}`.trim());
  return el(
    "div",
    { id: "tuning" },
    el("h3", {}, "Tuned values"),
    el(
      "table",
      {},
      el("thead", {}, el("tr", {}, el("th", {}, "tuned"), types.map((t) => el("th", { class: "num" }, t)))),
      el(
        "tbody",
        {},
        keys.map((k) =>
          el(
            "tr",
            {},
            el("td", {}, TUNED_NAMES[k] || k),
            types.map((t) => {
              const tt = answer.tuning[t];
              const unit = (tt.units || {})[k];
              const range = (tt.ranges || {})[k];
              return el("td", { class: "num", title: range ? `reachable: ${shown(k, range[0], unit)} … ${shown(k, range[1], unit)}` : null }, shown(k, tt.values[k], unit));
            })
          )
        ),
        el("tr", {}, el("td", {}, "smallest margin when tuned"), types.map((t) => el("td", { class: "num" }, percentText(answer.tuning[t].worst_margin))))
      )
    ),
    el("p", { class: "muted" }, "Each type's frequencies and damping set, within what the type can reach, to the largest smallest margin.")
  );
}

// The comparison as an engineer's answer: the recommendation, the criteria and the tuned values.
function renderComparisonAnswer(node, answer) {
  fill(node, recommendationNode(answer), criteriaTally(answer), criteriaTable(answer), tuningTable(answer));
}

// --------------------------------------------------------------------------------- optimisation
function parameterText(value, p, written) {
  if (value === null || value === undefined) return "–";
  if (written && !written.categorical && written.display_scale) {
    const u = written.display_unit === "1" ? "" : written.display_unit;
    return `${fmt(value / written.display_scale)} ${u}`.trim();
  }
  return quantityText(value, p.unit || "1");
}

function marginsTable(criteria, best, id) {
  return el(
    "table",
    { id },
    el("thead", {}, el("tr", {}, ["criterion", "limit", "value", "margin", ""].map((h) => el("th", {}, h)))),
    el(
      "tbody",
      {},
      criteria.map((c) => {
        const m = best.margins[c.name];
        return el("tr", {}, el("td", { title: c.name }, c.description), el("td", {}, criterionLimit(c)), el("td", { class: "num" }, criterionValue(c, m)), el("td", { class: "num margin" }, percentText(m)), el("td", {}, verdict(m)));
      })
    )
  );
}

// ``text`` broken into lines of at most about ``width`` characters (Plotly's <br>), so that a long axis
// title stays within its plot instead of running off its end.
function wrapWords(text, width) {
  const lines = [];
  for (const word of text.split(" ")) {
    const last = lines.length - 1;
    if (last >= 0 && lines[last].length + 1 + word.length <= width) lines[last] += ` ${word}`;
    else lines.push(word);
  }
  return lines.join("<br>");
}

function drawProgress(plotNode, opt) {
  const obj = opt.objective;
  const finite = opt.progress.map((p) => p.best).filter((v) => v !== null);
  const sample = quantityText(finite.length ? finite[0] : 1, obj.unit).split(" ");
  const unit = sample.length > 1 ? sample[1] : "";
  const one = unit && READABLE[obj.unit] ? READABLE[obj.unit].find(([u]) => u === unit)[1] : 1;
  const scale = (v) => (v === null ? null : v / one);
  const gens = opt.progress.map((p) => p.generation);
  const c = opt.cloud || { generation: [], objective: [], feasible: [], pareto: [], case: [] };
  const idx = (want) => c.generation.map((_, i) => i).filter((i) => want(i) && c.objective[i] !== null);
  const cloud = (name, pick, colour, size) => ({
    type: "scatter",
    mode: "markers",
    name,
    x: pick.map((i) => c.generation[i]),
    y: pick.map((i) => scale(c.objective[i])),
    customdata: pick.map((i) => c.case[i]),
    marker: { color: colour, size, opacity: 0.7 },
    hovertemplate: "case %{customdata}<br>generation %{x}: %{y}<extra>%{fullData.name}</extra>",
  });
  const traces = [
    cloud("infeasible cases", idx((i) => !c.feasible[i]), "#bbb", 5),
    cloud("feasible cases", idx((i) => c.feasible[i] && !c.pareto[i]), "#1f77b4", 6),
    cloud("front (non-dominated)", idx((i) => c.pareto[i]), "#2ca02c", 9),
    // markers too: a run whose first feasible case comes in its last generation has one point to show
    { type: "scatter", mode: "lines+markers", line: { shape: "hv", color: "#d62728", width: 2 }, marker: { size: 5 }, name: "best so far", x: gens, y: opt.progress.map((p) => scale(p.best_so_far)) },
  ];
  const layout = {
    height: 380,
    margin: { t: 20, r: 20, b: 50, l: 90 },
    xaxis: { title: { text: "generation" }, dtick: gens.length < 15 ? 1 : undefined, zeroline: false },
    yaxis: { title: { text: wrapWords(`${obj.long_name}${unit ? ` [${unit}]` : ""}`, 45), font: { size: 11 } } },
    legend: { orientation: "h", y: -0.2 },
  };
  fill(plotNode);
  Plotly.newPlot(plotNode, traces, layout, PLOT_CONFIG);
}

// An optimisation's answer: progress per generation, the cloud and front, the best design with its range
// limits and plateau, its margins. ``design`` is the study's parameters as written (/studies/{id}/design).
function renderOptimisation(node, answer, design) {
  const opt = answer.optimisation;
  const written = Object.fromEntries(((design && design.parameters) || []).map((p) => [p.name, p]));
  const plot = el("div", { id: "progress", class: "plot" });
  const parts = [];
  if (opt.best_case === null || opt.best_case === undefined) {
    parts.push(el("div", { class: "answer warn", id: "best-design" }, "No feasible case: no design the optimiser tried meets its constraints."));
  } else {
    const obj = opt.objective;
    parts.push(
      el(
        "div",
        { class: "answer ok", id: "best-design" },
        el("strong", {}, `Best design: case ${opt.best_case}`),
        ` (generation ${opt.best_generation}), ${obj.long_name} ${quantityText(opt.best_objectives[obj.quantity], obj.unit)}.`
      )
    );
    const rows = opt.parameters.map((p) => {
      const w = written[p.name];
      const flag = p.at_limit ? el("span", { class: "flag" }, `at the ${p.at_limit} end of its range: the optimum may lie beyond`) : "";
      return el(
        "tr",
        { class: p.at_limit ? "at-limit" : null },
        el("td", { title: p.long_name }, p.name),
        el("td", { class: "num" }, parameterText(p.best, p, w)),
        el("td", {}, `${parameterText(p.low, p, w)} … ${parameterText(p.high, p, w)}`),
        el("td", {}, p.plateau ? `${parameterText(p.plateau[0], p, w)} … ${parameterText(p.plateau[1], p, w)}` : "–"),
        el("td", {}, flag)
      );
    });
    parts.push(
      el(
        "table",
        { id: "best-parameters" },
        el("thead", {}, el("tr", {}, ["parameter", "best", "range", "plateau", ""].map((h) => el("th", {}, h)))),
        el("tbody", {}, rows)
      )
    );
    if (opt.best_margins) parts.push(el("h3", {}, "Margins of the best design"), marginsTable(answer.question.criteria || [], opt.best_margins, "best-margins"));
  }
  parts.push(
    el(
      "p",
      { class: "muted" },
      `${opt.algorithm}: ${opt.generations} generations, ${opt.n_cases} cases, ${opt.n_feasible} feasible, ${opt.n_pareto} on the front` +
        (opt.n_plateau !== undefined ? `; the plateau holds ${opt.n_plateau} feasible cases within ${fmt(100 * opt.plateau, 3)} % of the best objective` : "") +
        (opt.stopped ? `; stopped: ${opt.stopped === "stalled" ? "no more improvement" : opt.stopped}` : "") +
        "."
    )
  );
  fill(node, plot, parts);
  drawProgress(plot, opt);
  plot.on("plotly_click", (ev) => {
    const p = ev.points && ev.points[0];
    if (p && p.customdata !== undefined) location.href = `/ui/studies/${studyIdFromPath()}/cases/${p.customdata}`;
  });
}

// A study's criteria (no optimisation): how many cases meet them all, and the margins of the best one.
function renderStudyCriteria(node, answer) {
  const c = answer.criteria;
  const n = answer.n_cases;
  const head = c.n_meeting
    ? el("div", { class: "answer ok", id: "criteria-answer" }, `${c.n_meeting} of ${n} cases meet every criterion.`)
    : el("div", { class: "answer warn", id: "criteria-answer" }, `No case meets every criterion (${n} cases).`);
  fill(
    node,
    head,
    c.best_case ? [el("h3", {}, `Largest smallest margin: case ${c.best_case.case} (${c.best_case.label})`), marginsTable(answer.question.criteria, c.best_case, "best-margins")] : null
  );
}

// ---------------------------------------------------------------------------------- sensitivity
function drawSensitivity(node, result) {
  const names = result.parameters.map((p, i) => {
    const long = (result.parameter_long_names || [])[i];
    return long && long !== p ? long : p.replaceAll("_", " ");
  });
  const colours = { S1: "#1f77b4", ST: "#d62728", delta: "#2ca02c" };
  const traces = Object.entries(result.indices).map(([index, values]) => ({
    type: "bar",
    orientation: "h",
    name: `${index}${result.index_meanings && result.index_meanings[index] ? `: ${result.index_meanings[index]}` : ""}`,
    y: names,
    x: values,
    error_x: { type: "data", array: (result.conf || {})[index] || [], visible: true },
    marker: { color: colours[index] || "#888" },
  }));
  const layout = {
    height: 120 + 40 * names.length * Math.max(1, traces.length),
    barmode: "group",
    margin: { t: 20, r: 20, b: 50, l: 220 },
    xaxis: { title: { text: `index (${Math.round(100 * (result.conf_level || 0.95))} % intervals)` }, range: [0, 1.05] },
    yaxis: { automargin: true, autorange: "reversed" },
    legend: { orientation: "h", y: -0.25 },
  };
  fill(node);
  Plotly.newPlot(node, traces, layout, PLOT_CONFIG);
}

// ---------------------------------------------------------------------------------------- floor
// Floor vibration at each point of interest against the VC curves (/comparisons/floor or
// /studies/{id}/cases/{case}/floor): one plot a point, a line a type (µm/s, bands in Hz, log axes), the curve
// the point's velocity criterion names drawn bold.
const UM_PER_S = 1e6;
const AXIS_CHOICES = [["largest", "largest of x, y, z"], ["x", "x"], ["y", "y"], ["z", "z"]];

// Each band's value on the chosen axis, or the largest of the three (null where a value is missing, and
// where it is zero: a band the floor leaves still has no place on the log axis, and a zero drawn there
// would drop the line straight down).
function bandValues(perAxis, axis) {
  const pick = axis === "largest" ? ["x", "y", "z"] : [axis];
  return perAxis[pick[0]].map((_, b) => {
    const vs = pick.map((a) => perAxis[a][b]);
    if (vs.some((v) => v === null || v === undefined)) return null;
    const top = Math.max(...vs);
    return top > 0 ? top * UM_PER_S : null;
  });
}

function floorTraces(spectra, point, axis) {
  const f = spectra.nominal_centres;
  const judged = spectra.criteria[point];
  const traces = spectra.curves.map((c) => {
    const inside = f.filter((x) => x >= c.low && x <= c.high);
    const mine = c.name === judged;
    const iso = c.name.includes("ISO");
    return {
      type: "scatter",
      mode: "lines",
      name: mine ? `${c.name}: the criterion at ${point}` : c.name,
      x: inside,
      y: inside.map(() => c.velocity * UM_PER_S),
      line: mine ? { color: "#d62728", width: 3.5 } : { color: iso ? "#c9c9c9" : "#9a9a9a", width: 1, dash: "dot" },
      hovertemplate: `${c.name}: %{y:.3g} µm/s<extra></extra>`,
      showlegend: mine,
      meta: c.name,
    };
  });
  for (const c of spectra.curves) {
    // the curve's name at its right end, as on the usual chart
    traces.push({ type: "scatter", mode: "text", x: [c.high], y: [c.velocity * UM_PER_S], text: [c.name], textposition: "middle right", showlegend: false, hoverinfo: "skip", textfont: { size: 10, color: c.name === judged ? "#d62728" : "#777" } });
  }
  traces.push({
    type: "scatter",
    mode: "lines",
    name: "floor",
    x: f,
    y: bandValues(spectra.floor, axis),
    line: { color: "#444", width: 1.5, dash: "dash" },
    hovertemplate: "floor %{x} Hz: %{y:.3g} µm/s<extra></extra>",
  });
  spectra.isolator_types.forEach((t, k) => {
    traces.push({
      type: "scatter",
      mode: "lines+markers",
      name: `${t} isolators`,
      x: f,
      y: bandValues(spectra.velocity[t][point], axis),
      line: { color: (typeof TYPE_COLOURS !== "undefined" && TYPE_COLOURS[t]) || PALETTE[k % PALETTE.length], width: 2.5 },
      marker: { size: 5 },
      hovertemplate: `${t} %{x} Hz: %{y:.3g} µm/s<extra></extra>`,
    });
  });
  return traces;
}

// Each type's largest band at the point, and whether it stays within the criterion's curve.
function floorSummary(spectra, point) {
  const judged = spectra.criteria[point];
  const level = judged ? (spectra.curves.find((c) => c.name === judged) || {}).velocity : null;
  return el(
    "ul",
    { class: "floor-summary", "data-point": point },
    spectra.isolator_types.map((t) => {
      const w = spectra.worst[t][point];
      if (w.velocity === null) return el("li", {}, `${t}: not computed (a mechanism or a tipping case)`);
      const text = `${t}: largest band ${fmt(w.velocity * UM_PER_S, 3)} µm/s at ${fmt(w.band, 3)} Hz (${w.axis})`;
      if (!level) return el("li", {}, text + ".");
      const within = w.velocity <= level;
      return el("li", {}, text + ", ", el("span", { class: within ? "pass" : "fail" }, within ? `within ${judged}` : `above ${judged}`), ".");
    })
  );
}

// Draw the spectra of every point into ``node``; ``extra`` (a node or null) goes under the controls.
function renderFloorSpectra(node, spectra, extra) {
  const axisSelect = el("select", { id: "floor-axis" }, AXIS_CHOICES.map(([v, label]) => el("option", { value: v }, label)));
  const plots = spectra.points.map((p) => [p, el("div", { class: "plot floor-plot", id: `floor-plot-${p}`, "data-point": p })]);
  const draw = () => {
    const axis = axisSelect.value;
    for (const [p, div] of plots) {
      const layout = {
        height: 360,
        title: { text: `${p}${spectra.case !== null && spectra.case !== undefined ? ` (case ${spectra.case})` : ""}`, font: { size: 13 } },
        margin: { t: 40, r: 60, b: 50, l: 70 },
        xaxis: { type: "log", title: { text: "one-third-octave band centre [Hz]" }, range: [Math.log10(0.9), Math.log10(130)] },
        yaxis: { type: "log", title: { text: "RMS velocity [µm/s]" }, exponentformat: "none" },
        legend: { orientation: "h", y: -0.22 },
      };
      Plotly.react(div, floorTraces(spectra, p, axis), layout, PLOT_CONFIG);
    }
  };
  axisSelect.addEventListener("change", draw);
  fill(
    node,
    el("div", { class: "controls" }, el("label", {}, "axis ", axisSelect), extra || null),
    plots.map(([p, div]) => [div, floorSummary(spectra, p)]),
    el("p", { class: "muted" }, "One-third-octave RMS velocity under the floor's spectrum (steady state), against the generic vibration criteria VC-A … VC-G (and the ISO workshop and office lines).")
  );
  draw();
}
