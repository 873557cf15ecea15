// /ui/scene: build or change a scene with forms in units, checked by the service as you type (the same
// details as a run, shown at their field); see the machine in 3D with what the service computes from it
// (base mass, inertia and c.g., mount loads and frequencies, modes); run it at once (POST /simulations),
// read the answer in words, play its motion back, and compare with the run before.
"use strict";

const CHECK_DELAY_MS = 300;
const DRAFT_KEY = "isolab-draft";
const DRAFT_SCENE_KEY = "isolab-draft-scene"; // read by /ui/compare?from=draft
const PRESETS = ["air", "elastomer", "active"];
const EMPTY_SCENE = {
  machine: { block: { size: ["1 m", "1 m", "0.2 m"], density: "2700 kg/m^3", corner: [0, 0, 0] } },
  isolators: { preset: "air", layout: { span_x: "0.8 m", span_y: "0.8 m", height: "0.3 m" } },
  stages: [],
  points: {},
};

let scene = null; // the scene as the forms hold it (units as text where typed so)
let view = null; // the service's view of the last scene that passed its check
let fields = new Map(); // JSON of a path in the scene -> its field's node
let checkSeq = 0;
let checkTimer = null;
let runs = []; // the latest run first, the one before second
let runCount = 0;
let playTimer = null;

// ------------------------------------------------------------------------------------ scene data
const key = (path) => JSON.stringify(path);

function getAt(obj, path) {
  return path.reduce((o, p) => (o === undefined || o === null ? undefined : o[p]), obj);
}

function setAt(obj, path, value) {
  let o = obj;
  path.slice(0, -1).forEach((p, i) => {
    if (o[p] === undefined || o[p] === null) o[p] = typeof path[i + 1] === "number" ? [] : {};
    o = o[p];
  });
  const last = path[path.length - 1];
  if (value === undefined) {
    if (Array.isArray(o)) o[last] = null;
    else delete o[last];
  } else o[last] = value;
}

// A typed value: a plain number goes as a number (SI), anything else as text the service reads with
// its unit ("2 g", "3.5 Hz"); an empty box leaves the value out.
function parsed(text) {
  const t = text.trim();
  if (!t) return undefined;
  if (/^[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$/.test(t)) return Number(t);
  return t;
}

// What the forms leave empty goes out of the scene sent: empty criteria, floor and k/c blocks, and vectors
// with every box empty (a required one is then named missing at its field).
function pruned(value) {
  if (value === undefined || value === null || value === "") return undefined;
  if (Array.isArray(value)) return value.every((v) => v === undefined || v === null || v === "") ? undefined : value.map((v) => (v === undefined ? null : v));
  if (typeof value !== "object") return value;
  const out = {};
  for (const [k, v] of Object.entries(value)) {
    const p = pruned(v);
    if (p !== undefined) out[k] = p;
  }
  return Object.keys(out).length ? out : undefined;
}

function sentScene() {
  const out = structuredClone(scene);
  const tidy = (obj, keys) => {
    for (const k of keys) {
      if (!obj || !(k in obj)) continue;
      const p = pruned(obj[k]);
      if (p === undefined) delete obj[k];
      else obj[k] = p;
    }
  };
  tidy(out, ["criteria", "floor"]);
  tidy(out.isolators, ["k", "c"]);
  for (const mount of (out.isolators && out.isolators.list) || []) tidy(mount, ["k", "c"]);
  if (out.criteria) for (const c of Object.values(out.criteria)) if (c && c.no_liftoff === false) delete c.no_liftoff;
  return out;
}

function shown(value) {
  return value === undefined || value === null ? "" : String(value);
}

// ---------------------------------------------------------------------------------------- forms
// One labelled row of inputs: one input per path, the unit, and the service's problem under it.
function field(label, paths, unit, opts = {}) {
  const errorNode = el("div", { class: "field-error" });
  const row = el("div", { class: "field" });
  const inputs = paths.map((path, i) =>
    el("input", {
      type: "text",
      value: opts.show ? opts.show(getAt(scene, path)) : shown(getAt(scene, path)),
      placeholder: Array.isArray(opts.placeholder) ? opts.placeholder[i] : opts.placeholder || null,
      "aria-label": paths.length > 1 ? `${label} ${"xyz"[i]}` : label,
      "data-path": key(path),
      oninput: (e) => {
        const text = e.target.value;
        setAt(scene, path, opts.read ? opts.read(text) : opts.text ? text.trim() || undefined : parsed(text));
        scheduleCheck();
      },
    })
  );
  row.append(el("label", {}, label), el("div", { class: "inputs" }, inputs, unit ? el("span", { class: "unit" }, unit) : null), errorNode);
  row.errorNode = errorNode;
  for (const p of paths) fields.set(key(p), row);
  if (opts.group) fields.set(key(opts.group), row);
  return row;
}

const vec = (path) => [0, 1, 2].map((i) => [...path, i]);

function selectField(label, path, options, onchange) {
  const current = getAt(scene, path);
  const node = el(
    "select",
    { "aria-label": label, "data-path": key(path), onchange: (e) => onchange(e.target.value) },
    options.map(([value, text]) => el("option", { value, selected: shown(current) === value }, text))
  );
  const errorNode = el("div", { class: "field-error" });
  const row = el("div", { class: "field" }, el("label", {}, label), el("div", { class: "inputs" }, node), errorNode);
  row.errorNode = errorNode;
  fields.set(key(path), row);
  return row;
}

function section(title, path, ...children) {
  const errorNode = el("div", { class: "field-error" });
  const node = el("fieldset", { class: "form" }, el("legend", {}, title), children, errorNode);
  node.errorNode = errorNode;
  fields.set(key(path), node);
  return node;
}

function mountFreq(j, what) {
  const m = view && view.mounts[j];
  return m && m[what] !== null && m[what] !== undefined ? `${fmt(m[what], 3)} now` : "";
}

// The stiffness (k) or damping (c) of mount j along each axis now, as the placeholders of its fields.
function mountNow(j, what) {
  const m = view && view.mounts[j];
  return m ? m[what].map((v) => `${fmt(v, 3)} now`) : null;
}

// Explicit stiffness and damping along X, Y, Z: instead of the frequencies and damping ratio.
function explicitFields(at, j) {
  const group = !at.includes("list");
  const axes = (what) => (group ? ["x", "y", "z"].map((a) => [...at, what, a]) : vec([...at, what]));
  return [
    field("stiffness k", axes("k"), "N/m (X, Y, Z)", { group: [...at, "k"], placeholder: mountNow(group ? 0 : j, "stiffness") }),
    field("damping c", axes("c"), "N s/m (X, Y, Z)", { group: [...at, "c"], placeholder: mountNow(group ? 0 : j, "damping") }),
  ];
}

function baseForm() {
  const m = scene.machine;
  const isBlock = Boolean(m.block);
  const kind = selectField("given as", ["machine", "_kind"], [["block", "a block: size and density"], ["given", "mass, inertia and c.g."]], (v) => {
    if (v === "block") scene.machine = { block: { size: view ? view.base.box_size : [1, 1, 0.2], density: "2700 kg/m^3", corner: view ? view.base.box_corner : [0, 0, 0] } };
    else if (view) {
      const I = view.base.inertia;
      scene.machine = { mass: view.base.mass, cg: view.base.cg, inertia_diagonal: [I[0][0], I[1][1], I[2][2]] };
    } else scene.machine = { mass: 1000, cg: [0, 0, 0.2], inertia_diagonal: [100, 100, 100] };
    renderForms();
  });
  kind.querySelector("select").value = isBlock ? "block" : "given";
  const rows = isBlock
    ? [
        field("size", vec(["machine", "block", "size"]), "m", { group: ["machine", "block", "size"] }),
        field("density", [["machine", "block", "density"]], "kg/m³"),
        field("min. corner", vec(["machine", "block", "corner"]), "m", { group: ["machine", "block", "corner"] }),
      ]
    : [
        field("mass", [["machine", "mass"]], "kg"),
        field("c.g.", vec(["machine", "cg"]), "m", { group: ["machine", "cg"] }),
        m.inertia
          ? [0, 1, 2].map((r) => field(`inertia row ${r + 1}`, vec(["machine", "inertia", r]), "kg m²", { group: ["machine", "inertia"] }))
          : field("inertia Ixx Iyy Izz", vec(["machine", "inertia_diagonal"]), "kg m²", { group: ["machine", "inertia_diagonal"] }),
      ];
  return section("Base", ["machine"], kind, rows, el("div", { id: "base-computed", class: "computed" }, "…"));
}

function isolatorForm() {
  const iso = scene.isolators;
  const preset = selectField("type", ["isolators", "preset"], PRESETS.map((p) => [p, p]), (v) => {
    iso.preset = v;
    scheduleCheck();
  });
  const tuned = iso.tuning && Object.keys(iso.tuning).length
    ? el("p", { class: "muted" }, `The scene tunes ${Object.keys(iso.tuning).join(", ")}; a value typed here overrides the tuning for every mount.`)
    : null;
  const group = [
    field("vertical freq.", [["isolators", "f_vertical"]], "Hz", { placeholder: mountFreq(0, "f_vertical") }),
    field("horizontal freq.", [["isolators", "f_horizontal"]], "Hz", { placeholder: mountFreq(0, "f_horizontal") }),
    field("damping ratio", [["isolators", "zeta"]], "1", { placeholder: "of the type" }),
    el("p", { class: "muted" }, "Or give the stiffness and damping of every mount (they win over the frequencies and damping ratio):"),
    explicitFields(["isolators"], 0),
  ];
  let placement;
  if (iso.layout) {
    placement = [
      field("span X", [["isolators", "layout", "span_x"]], "m"),
      field("span Y", [["isolators", "layout", "span_y"]], "m"),
      field("c.g. above mounts", [["isolators", "layout", "height"]], "m"),
      el("button", {
        type: "button", class: "secondary", id: "place-mounts", disabled: !view,
        onclick: () => {
          iso.list = view.mounts.map((m) => ({ position: m.position.map((v) => Number(v.toPrecision(6))) }));
          delete iso.layout;
          renderForms();
          scheduleCheck();
        },
      }, "Place each mount"),
    ];
  } else {
    const list = iso.list || [];
    placement = list.map((mount, j) =>
      section(
        `${view && view.mounts[j] ? `${view.mounts[j].name} (${view.mounts[j].place})` : `mount ${j}`}`,
        ["isolators", "list", j],
        field("position", vec(["isolators", "list", j, "position"]), "m", { group: ["isolators", "list", j, "position"] }),
        selectField("type", ["isolators", "list", j, "preset"], [["", "the group's"], ...PRESETS.map((p) => [p, p])], (v) => {
          setAt(scene, ["isolators", "list", j, "preset"], v || undefined);
          scheduleCheck();
        }),
        field("vertical freq.", [["isolators", "list", j, "f_vertical"]], "Hz", { placeholder: mountFreq(j, "f_vertical") }),
        field("horizontal freq.", [["isolators", "list", j, "f_horizontal"]], "Hz", { placeholder: mountFreq(j, "f_horizontal") }),
        field("damping ratio", [["isolators", "list", j, "zeta"]], "1"),
        explicitFields(["isolators", "list", j], j),
        el("button", { type: "button", class: "secondary", disabled: list.length <= 3, onclick: () => { list.splice(j, 1); renderForms(); scheduleCheck(); } }, "Remove mount")
      )
    );
    placement.push(
      el("div", { class: "controls" },
        el("button", { type: "button", class: "secondary", onclick: () => { list.push({ position: [...list[list.length - 1].position] }); renderForms(); scheduleCheck(); } }, "Add mount"),
        el("button", { type: "button", class: "secondary", id: "layout-mounts", disabled: !view, onclick: layOutMounts }, "Lay four out around the c.g."))
    );
  }
  return section("Isolators", ["isolators"], preset, tuned, group, placement);
}

function stageForm() {
  const stages = scene.stages || (scene.stages = []);
  const blocks = stages.map((st, i) => {
    const at = (...p) => ["stages", i, ...p];
    return section(
      `stage ${st.name || i}`,
      at(),
      field("name", [at("name")], "", { text: true }),
      field("mass", [at("mass")], "kg"),
      field("home", vec(at("home")), "m", { group: at("home") }),
      field("axis", vec(at("axis")), "", { group: at("axis") }),
      field("rides on", [at("parent")], "stage", { text: true }),
      profileForm(i),
      el("button", { type: "button", class: "secondary", onclick: () => { stages.splice(i, 1); renderForms(); scheduleCheck(); } }, "Remove stage")
    );
  });
  const add = el("button", {
    type: "button", class: "secondary",
    onclick: () => {
      const cg = view ? view.base.cg : [0, 0, 0];
      stages.push({
        name: `stage${stages.length + 1}`, mass: "100 kg", home: [cg[0], cg[1], cg[2] + 0.3], axis: [1, 0, 0],
        profile: { type: "trapezoid", travel: "0.2 m", velocity: "0.5 m/s", acceleration: "5 m/s^2" },
      });
      renderForms();
      scheduleCheck();
    },
  }, "Add stage");
  return section("Stages", ["stages"], blocks, add);
}

function pointForm() {
  const points = scene.points || (scene.points = {});
  const rows = Object.keys(points).map((name) =>
    el("div", {}, field(name, vec(["points", name]), "m", { group: ["points", name] }),
      el("button", { type: "button", class: "secondary", onclick: () => {
        delete points[name];
        if (scene.criteria) delete scene.criteria[name];
        renderForms();
        scheduleCheck();
      } }, `Remove ${name}`))
  );
  const nameInput = el("input", { type: "text", placeholder: "name", size: "10", "aria-label": "new point name" });
  const add = el("button", {
    type: "button", class: "secondary",
    onclick: () => {
      const name = nameInput.value.trim();
      if (!name || name in points) return;
      points[name] = view ? [...view.base.cg] : [0, 0, 0];
      renderForms();
      scheduleCheck();
    },
  }, "Add point");
  return section("Points of interest", ["points"], rows, el("div", { class: "controls" }, nameInput, add));
}

function renderForms() {
  fields = new Map();
  fill($("#forms"), baseForm(), isolatorForm(), stageForm(), pointForm(), criteriaForm(), floorForm());
  if (view) {
    showComputed();
    drawProfiles();
  }
}

// ------------------------------------------------------------------------------------- checking
function scheduleCheck() {
  clearTimeout(checkTimer);
  checkSeq++; // an answer still on its way is for the scene as it was: dropped when it lands
  $("#run").disabled = true;
  $("#check-status").className = "muted";
  $("#check-status").textContent = "Checking…";
  checkTimer = setTimeout(check, CHECK_DELAY_MS);
}

// The field a problem belongs to: the deepest path of the scene with a field (a profile's type tag,
// which the service puts in the path, left out).
function fieldOf(loc) {
  let path = loc.slice(loc[0] === "body" ? 2 : 0);
  const tag = path.indexOf("profile");
  if (tag >= 0 && typeof path[tag + 1] === "string" && /^(trapezoid|scurve|scan|sequence)$/.test(path[tag + 1])) {
    path = [...path.slice(0, tag + 1), ...path.slice(tag + 2)];
  }
  const seg = path.indexOf("segments");
  if (seg >= 0 && typeof path[seg + 1] === "number" && /^(move|dwell)$/.test(path[seg + 2]) && path.length > seg + 3) {
    path = [...path.slice(0, seg + 2), ...path.slice(seg + 3)];
  }
  for (let n = path.length; n > 0; n--) {
    const node = fields.get(key(path.slice(0, n)));
    if (node) return node;
  }
  return null;
}

function showProblems(details) {
  for (const node of document.querySelectorAll(".field.bad")) node.classList.remove("bad");
  for (const node of fields.values()) fill(node.errorNode);
  const loose = [];
  for (const d of details) {
    const node = fieldOf(d.loc || []);
    if (node) {
      node.classList.add("bad");
      node.errorNode.appendChild(el("div", {}, d.msg));
    } else loose.push(d.msg);
  }
  return loose;
}

async function check() {
  const seq = ++checkSeq;
  try {
    const answer = await postJson("/scenes/check", { scene: sentScene() });
    if (seq !== checkSeq) return;
    view = answer;
    showProblems([]);
    $("#check-status").className = "ok";
    $("#check-status").textContent = "✓ the service accepts the scene";
    $("#run").disabled = false;
    $("#download-yaml").disabled = false;
    Scene3D.stop();
    Scene3D.setView(view);
    showComputed();
    showModes();
    stopPlayback();
    ScenePlan.draw(view);
    drawProfiles();
  } catch (err) {
    if (seq !== checkSeq) return;
    const details = err.body && Array.isArray(err.body.detail) ? err.body.detail : [{ msg: err.message, loc: [] }];
    const loose = showProblems(details);
    $("#check-status").className = "error";
    $("#check-status").textContent = `${details.length} problem${details.length === 1 ? "" : "s"}${loose.length ? ": " + loose.join("; ") : " (at their fields)"}`;
    $("#download-yaml").disabled = true;
  }
}

// -------------------------------------------------------------------------- what the service computed
function mass(kg) {
  return kg >= 1000 ? `${fmt(kg / 1000, 4)} t` : `${fmt(kg, 4)} kg`;
}

function showComputed() {
  const b = view.base;
  const I = b.inertia;
  const node = $("#base-computed");
  if (node) {
    fill(
      node,
      el("div", {}, "Mass ", el("strong", { id: "base-mass" }, mass(b.mass)), ` (${fmt(b.mass, 6)} kg${b.source === "block" ? `, from ${fmt(b.density, 4)} kg/m³` : ""})`),
      el("div", {}, `Inertia about the c.g.: Ixx ${fmt(I[0][0], 4)}, Iyy ${fmt(I[1][1], 4)}, Izz ${fmt(I[2][2], 4)} kg m²`),
      el("div", {}, `c.g. at (${b.cg.map((v) => fmt(v, 4)).join(", ")}) m; with the stages ${mass(b.total_mass)}`)
    );
  }
  fill($("#base-facts"), `Base ${mass(b.mass)}, with its stages ${mass(b.total_mass)}: ${view.mounts.length} mounts, ${view.stages.length} stages, ${Object.keys(view.points).length} points of interest.`);
  const head = el("tr", {}, ["mount", "place", "x, y, z (m)", "static load (kN)", "vertical (Hz)", "horizontal (Hz)"].map((h) => el("th", {}, h)));
  const rows = view.mounts.map((m) =>
    el("tr", {}, el("td", {}, m.name), el("td", {}, m.place), el("td", {}, m.position.map((v) => fmt(v, 3)).join(", ")),
      el("td", {}, fmt(m.static_load / 1000, 4)), el("td", {}, fmt(m.f_vertical, 3)), el("td", {}, fmt(m.f_horizontal, 3)))
  );
  fill($("#mounts"), el("table", { id: "mount-table" }, el("thead", {}, head), el("tbody", {}, rows)));
}

function showModes() {
  const select = $("#mode");
  const before = select.value;
  fill(select, view.modes.map((m) => el("option", { value: String(m.mode - 1) }, `${m.mode}: ${m.name || "?"}, ${fmt(m.frequency, 3)} Hz, ζ ${fmt(100 * m.damping_ratio, 3)} %`)));
  if (before && Number(before) < view.modes.length) select.value = before;
}

function exaggeration() {
  const x = Number($("#exaggeration").value);
  return Number.isFinite(x) && x > 0 ? x : 1;
}

function animateMode() {
  if (!view) return;
  stopPlayback();
  const m = view.modes[Number($("#mode").value) || 0];
  if (Scene3D.modeTimer && $("#animate-mode").dataset.mode === String(m.mode)) {
    Scene3D.stop();
    Scene3D.pose([0, 0, 0, 0, 0, 0], null);
    $("#animate-mode").textContent = "Animate mode";
    delete $("#animate-mode").dataset.mode;
    return;
  }
  Scene3D.animateMode(m.shape, exaggeration());
  $("#animate-mode").dataset.mode = String(m.mode);
  $("#animate-mode").textContent = "Stop mode";
}

// ----------------------------------------------------------------------------------------- running
async function run() {
  $("#run").disabled = true;
  fill($("#error"));
  $("#check-status").className = "muted";
  $("#check-status").textContent = "Running…";
  const started = performance.now();
  try {
    const answer = await postJson("/simulations", { scene: sentScene(), max_points: 1000 });
    runs = [{ answer, n: ++runCount, seconds: (performance.now() - started) / 1000 }, ...runs].slice(0, 2);
    $("#check-status").className = "ok";
    $("#check-status").textContent = `✓ run ${runCount} answered in ${fmt(runs[0].seconds, 2)} s`;
    showSummary();
    drawTraces();
    startPlaybackControls();
  } catch (err) {
    showError("#error", err);
    $("#check-status").textContent = "";
  } finally {
    $("#run").disabled = false;
  }
}

// A value of the summary in the unit an engineer reads it in.
function quantity(item) {
  if (!item || item.value === null || item.value === undefined) return "–";
  const v = item.value;
  if (typeof v !== "number") return fmt(v);
  if (item.unit === "m") return `${fmt(v * 1e3, 3)} mm`;
  if (item.unit === "rad") return `${fmt(v * 1e3, 3)} mrad`;
  if (item.unit === "N") return Math.abs(v) >= 1000 ? `${fmt(v / 1e3, 3)} kN` : `${fmt(v, 3)} N`;
  if (item.unit === "1") return fmt(v, 3);
  return `${fmt(v, 3)} ${item.unit}`;
}

function showSummary() {
  const [now, before] = runs;
  const s = now.answer.summary;
  const was = (k) => (before && before.answer.summary[k] ? ` (was ${quantity(before.answer.summary[k])})` : "");
  const item = (label, k) => el("span", { class: "peak", "data-key": k }, `${label} ${quantity(s[k])}${was(k)}`);
  const list = (pairs) => pairs.flatMap(([label, k], i) => [i ? ", " : "", item(label, k)]);
  const model = now.answer.model;
  const points = Object.keys(now.answer.traces.point_displacement || {});
  const margins = Object.keys(s).filter((k) => k.startsWith("criterion_margin"));
  const p = (...c) => el("p", {}, c);
  fill(
    $("#summary"),
    p(el("strong", {}, `Run ${now.n}`), `: ${now.answer.status}${now.answer.message ? ` (${now.answer.message})` : ""}; ${model.fidelity}/${model.integrator} at ${fmt(model.dt * 1e3, 3)} ms over ${fmt(model.duration, 3)} s, in ${fmt(model.engine_seconds, 2)} s of engine time.${before ? ` Run ${before.n}, before the change, is drawn dotted.` : ""}`),
    p("Peak c.g. displacement: ", list([["X", "peak_displacement_x"], ["Y", "peak_displacement_y"], ["Z", "peak_displacement_z"]]), "."),
    p("Peak base rotation: ", list([["rx", "peak_rotation_rx"], ["ry", "peak_rotation_ry"], ["rz", "peak_rotation_rz"]]), "."),
    points.map((pt) => p(`Peak displacement at ${pt}: `, list([["X", `peak_point_displacement_${pt}_x`], ["Y", `peak_point_displacement_${pt}_y`], ["Z", `peak_point_displacement_${pt}_z`]]), ".")),
    p("Peak dynamic isolator force: ", list([["X", "peak_isolator_force_x"], ["Y", "peak_isolator_force_y"], ["Z", "peak_isolator_force_z"]]),
      `; vertical loads between ${quantity(s.min_isolator_load_min)} and ${quantity(s.max_isolator_load_max)}, ${s.liftoff_any && s.liftoff_any.value ? "an isolator LIFTS OFF" : "no isolator lifts off"}.`),
    p(`Settling: ${now.answer.settling_time === null ? "–" : `${fmt(now.answer.settling_time, 3)} s`} after the last move${now.answer.settled ? "" : " (not settled before the end: a lower bound)"}.`),
    p("Modes: ", now.answer.modes.map((m) => `${fmt(m.frequency, 3)} Hz ${m.name} (ζ ${fmt(100 * m.damping_ratio, 2)} %)`).join(", "), "."),
    margins.length
      ? p("Criteria: ", margins.map((k) => `${s[k].long_name}: margin ${fmt(100 * s[k].value, 3)} %`).join("; "),
          s.meets_criteria ? (s.meets_criteria.value ? " — every criterion is met." : " — NOT every criterion is met.") : "")
      : null
  );
}

const TRACE_ROWS = [
  ["displacement", ["x", "y", "z"], "c.g. displacement (mm)", 1e3],
  ["rotation", ["rx", "ry", "rz"], "base rotation (mrad)", 1e3],
];

function drawTraces() {
  const data = [];
  runs.forEach((r, age) => {
    const t = r.answer.traces;
    const style = age ? { dash: "dot", width: 1.5 } : { width: 1.5 };
    const suffix = age ? ` (run ${r.n}, before)` : ` (run ${r.n})`;
    TRACE_ROWS.forEach(([name, comps, , scale], row) =>
      comps.forEach((c, i) =>
        data.push({
          x: t.time, y: t[name][c].map((v) => (v === null ? null : v * scale)), name: `${c}${suffix}`, xaxis: "x", yaxis: row ? `y${row + 1}` : "y",
          line: { ...style, color: PALETTE[i] }, opacity: age ? 0.6 : 1, legendgroup: `run${r.n}`,
        })
      )
    );
    Object.entries(t.isolator_force).forEach(([iso, f], i) => {
      const place = r.answer.isolators[iso] ? r.answer.isolators[iso].place : iso;
      data.push({
        x: t.time, y: f.z.map((v) => (v === null ? null : v / 1e3)), name: `${place} Z${suffix}`, xaxis: "x", yaxis: "y3",
        line: { ...style, color: PALETTE[(i + 3) % PALETTE.length] }, opacity: age ? 0.6 : 1, legendgroup: `run${r.n}`,
      });
    });
  });
  const layout = {
    height: 760,
    margin: { t: 20, r: 20 },
    grid: { rows: 3, columns: 1, shared_xaxes: true },
    xaxis: { title: { text: "time (s)" }, anchor: "y3" },
    yaxis: { title: { text: TRACE_ROWS[0][2] }, domain: [0.7, 1] },
    yaxis2: { title: { text: TRACE_ROWS[1][2] }, domain: [0.37, 0.65] },
    // two lines: on one the title is longer than its panel and runs into the rotation's
    yaxis3: { title: { text: "dynamic vertical<br>isolator force (kN)" }, domain: [0, 0.32] },
    shapes: [{ type: "line", xref: "x", yref: "paper", x0: 0, x1: 0, y0: 0, y1: 1, line: { color: "#444", width: 1 } }],
    legend: { orientation: "h", y: -0.08 },
  };
  Plotly.react($("#traces"), data, layout, PLOT_CONFIG);
  $("#traces").dataset.runs = String(runs.length);
}

// ---------------------------------------------------------------------------------------- playback
function startPlaybackControls() {
  const n = runs[0].answer.traces.time.length;
  const slider = $("#time");
  slider.max = String(n - 1);
  slider.value = "0";
  slider.disabled = false;
  $("#play").disabled = false;
  showTime(0);
}

function showTime(i) {
  const a = runs[0].answer;
  const t = a.traces;
  const x = exaggeration();
  const at = (series) => (series[i] === null ? 0 : series[i]);
  const q = [at(t.displacement.x), at(t.displacement.y), at(t.displacement.z), at(t.rotation.rx), at(t.rotation.ry), at(t.rotation.rz)].map((v) => v * x);
  const along = Object.fromEntries(Object.entries(t.stages || {}).map(([name, s]) => [name, at(s.position)]));
  Scene3D.pose(q, along);
  $("#time-label").textContent = `t = ${fmt(t.time[i], 3)} s`;
  Plotly.relayout($("#traces"), { "shapes[0].x0": t.time[i], "shapes[0].x1": t.time[i] });
}

function stopPlayback() {
  if (playTimer) cancelAnimationFrame(playTimer);
  playTimer = null;
  $("#play").textContent = "Play the run";
}

function togglePlay() {
  if (playTimer) return stopPlayback();
  Scene3D.stop();
  $("#animate-mode").textContent = "Animate mode";
  const time = runs[0].answer.traces.time;
  const slider = $("#time");
  let i0 = Number(slider.value);
  if (i0 >= time.length - 1) i0 = 0;
  const t0 = time[i0];
  const started = performance.now();
  let shownAt = 0;
  const frame = (now) => {
    const t = t0 + (now - started) / 1000;
    let i = Number(slider.value);
    while (i < time.length - 1 && time[i + 1] <= t) i++;
    if (now - shownAt > 50) {
      slider.value = String(i);
      showTime(i);
      shownAt = now;
    }
    if (i >= time.length - 1) return stopPlayback();
    playTimer = requestAnimationFrame(frame);
  };
  $("#play").textContent = "Pause";
  playTimer = requestAnimationFrame(frame);
}

// ------------------------------------------------------------------------------------ the sources
function downloadYaml() {
  if (!view) return;
  const url = URL.createObjectURL(new Blob([view.yaml], { type: "application/yaml" }));
  const a = el("a", { href: url, download: "scene.yaml" });
  document.body.appendChild(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 10000);
}

function startStudy(e) {
  if (!view) return;
  sessionStorage.setItem(DRAFT_KEY, view.study_yaml);
  e.currentTarget.href = "/ui/new?from=draft";
}

// The scene handed to /ui/compare: each isolator type under it, side by side.
function compareTypes(e) {
  if (!view) {
    e.preventDefault();
    return;
  }
  sessionStorage.setItem(DRAFT_SCENE_KEY, JSON.stringify(sentScene()));
  e.currentTarget.href = "/ui/compare?from=draft";
}

async function loadSources() {
  const select = $("#source");
  try {
    const examples = await apiJson("/scenes/examples");
    select.appendChild(el("optgroup", { label: "Examples" }, examples.names.map((n) => el("option", { value: `example:${n}` }, n))));
    const stored = await apiJson("/studies?limit=100");
    if (stored.items.length) {
      select.appendChild(el("optgroup", { label: "Scenes of stored studies" }, stored.items.map((s) => el("option", { value: `study:${s.id}` }, `${s.name} (${when(s.created)})`))));
    }
  } catch (err) {
    showError("#error", err);
  }
}

async function loadSource(value) {
  const [kind, name] = value.split(/:(.*)/s);
  runs = [];
  try {
    if (kind === "example") {
      scene = (await apiJson(`/scenes/examples/${encodeURIComponent(name)}`)).scene;
      $("#title").textContent = `Scene: ${name}`;
      history.replaceState(null, "", `/ui/scene?example=${encodeURIComponent(name)}`);
    } else if (kind === "study") {
      const study = await apiJson(`/studies/${encodeURIComponent(name)}`);
      // the study's own floor and criteria replace its scene's, as when the study runs
      scene = { ...study.definition.scene };
      for (const part of ["floor", "criteria"]) if (study.definition[part]) scene[part] = study.definition[part];
      $("#title").textContent = `Scene of the study ${study.name}`;
      history.replaceState(null, "", `/ui/scene?study=${encodeURIComponent(name)}`);
    } else {
      scene = structuredClone(EMPTY_SCENE);
      $("#title").textContent = "Scene";
      history.replaceState(null, "", "/ui/scene");
    }
    fill($("#error"));
  } catch (err) {
    showError("#error", err);
    scene = structuredClone(EMPTY_SCENE);
  }
  view = null;
  renderForms();
  scheduleCheck();
}

header("scene");
Scene3D.node = $("#view3d");
$("#run").addEventListener("click", run);
$("#download-yaml").addEventListener("click", downloadYaml);
$("#start-study").addEventListener("click", startStudy);
$("#compare-types").addEventListener("click", compareTypes);
ScenePlan.node = $("#plan");
ScenePlan.onMove = moveMount;
$("#animate-mode").addEventListener("click", animateMode);
$("#mode").addEventListener("change", () => Scene3D.modeTimer && (Scene3D.stop(), animateMode()));
$("#play").addEventListener("click", togglePlay);
$("#time").addEventListener("input", (e) => {
  stopPlayback();
  Scene3D.stop();
  showTime(Number(e.target.value));
});
$("#source").addEventListener("change", (e) => loadSource(e.target.value));
const params = new URLSearchParams(location.search);
const first = params.get("example") ? `example:${params.get("example")}` : params.get("study") ? `study:${params.get("study")}` : "empty";
loadSources().then(() => {
  if ([...$("#source").options].some((o) => o.value === first)) $("#source").value = first;
  loadSource(first);
});
