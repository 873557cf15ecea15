// /ui/scene: a stage's motion profile: its type and numbers in units (a sequence as moves and dwells one
// after the other, each editable), and the plot of its position, velocity and acceleration against time as
// the service samples it from the engine's profile (POST /scenes/check: stages[i].profile); the page only
// draws what the service computed.
"use strict";

const PROFILE_TYPES = [
  ["trapezoid", "trapezoid: one move"],
  ["scurve", "S-curve: one jerk-limited move"],
  ["scan", "scan: out, dwell, back, dwell"],
  ["sequence", "sequence of moves and dwells"],
];
// the numbers of each type, in the order an engineer reads them: [key, label, unit]
const PROFILE_NUMBERS = {
  trapezoid: [["travel", "travel", "m"], ["velocity", "velocity", "m/s"], ["acceleration", "acceleration", "m/s² (or 2 g)"], ["start", "start", "s"]],
  scurve: [["travel", "travel", "m"], ["velocity", "velocity", "m/s"], ["acceleration", "acceleration", "m/s² (or 2 g)"], ["jerk", "jerk", "m/s³"], ["start", "start", "s"]],
  scan: [
    ["travel", "travel", "m"], ["velocity", "velocity", "m/s"], ["acceleration", "acceleration", "m/s² (or 2 g)"],
    ["jerk", "jerk", "m/s³ (S-curves)"], ["dwell", "dwell", "s"], ["repeats", "repeats", "times"], ["start", "start", "s"],
  ],
  sequence: [["start", "start", "s"]],
};
const MOVE_NUMBERS = [["move", "move by", "m"], ["velocity", "velocity", "m/s"], ["acceleration", "acceleration", "m/s² (or 2 g)"], ["jerk", "jerk", "m/s³ (S-curve)"]];
const PROFILE_ROWS = [
  ["position", "position (mm)", 1e3],
  ["velocity", "velocity (m/s)", 1],
  ["acceleration", "acceleration (m/s²)", 1],
];

// The profile changed to another type: the numbers both types have are kept.
function retypeProfile(stage, type) {
  const old = stage.profile || {};
  const prof = { type };
  const keep = PROFILE_NUMBERS[type].map(([k]) => k);
  for (const k of keep) if (old[k] !== undefined) prof[k] = old[k];
  if (type === "sequence") {
    prof.segments = old.segments || [
      { move: old.travel !== undefined ? old.travel : "0.1 m", velocity: old.velocity || "0.5 m/s", acceleration: old.acceleration || "5 m/s^2" },
    ];
  } else if (old.type === "sequence") {
    const move = (old.segments || []).find((s) => s && s.move !== undefined) || {};
    for (const k of ["velocity", "acceleration"]) if (move[k] !== undefined) prof[k] = move[k];
    prof.travel = move.move !== undefined ? move.move : "0.1 m";
  }
  if (prof.velocity === undefined && type !== "sequence") prof.velocity = "0.5 m/s";
  if (prof.acceleration === undefined && type !== "sequence") prof.acceleration = "5 m/s^2";
  if (prof.travel === undefined && type !== "sequence") prof.travel = "0.1 m";
  if (type === "scurve" && prof.jerk === undefined) prof.jerk = "100 m/s^3";
  stage.profile = prof;
}

function segmentForm(i, segments, k) {
  const at = ["stages", i, "profile", "segments", k];
  const seg = segments[k];
  const isDwell = seg && seg.dwell !== undefined && seg.move === undefined;
  const rows = isDwell
    ? [field("dwell", [[...at, "dwell"]], "s")]
    : MOVE_NUMBERS.map(([name, label, unit]) => field(label, [[...at, name]], unit));
  const buttons = el(
    "div",
    { class: "controls" },
    el("button", {
      type: "button", class: "secondary", disabled: k === 0,
      onclick: () => { segments.splice(k - 1, 2, segments[k], segments[k - 1]); renderForms(); scheduleCheck(); },
    }, "Earlier"),
    el("button", {
      type: "button", class: "secondary", disabled: segments.length <= 1,
      onclick: () => { segments.splice(k, 1); renderForms(); scheduleCheck(); },
    }, "Remove")
  );
  return section(`${k + 1}. ${isDwell ? "dwell" : "move"}`, at, rows, buttons);
}

// The profile part of stage i's form: its type, its numbers (or segments), and the plot's place.
function profileForm(i) {
  const stage = scene.stages[i];
  const prof = stage.profile || (stage.profile = { type: "trapezoid" });
  const type = selectField("profile", ["stages", i, "profile", "type"], PROFILE_TYPES, (v) => {
    retypeProfile(stage, v);
    renderForms();
    scheduleCheck();
  });
  const numbers = (PROFILE_NUMBERS[prof.type] || []).map(([k, label, unit]) => field(label, [["stages", i, "profile", k]], unit));
  let segments = null;
  if (prof.type === "sequence") {
    const list = prof.segments || (prof.segments = []);
    segments = [
      list.map((_, k) => segmentForm(i, list, k)),
      el("div", { class: "controls" },
        el("button", {
          type: "button", class: "secondary",
          onclick: () => {
            const last = [...list].reverse().find((s) => s && s.move !== undefined) || { velocity: "0.5 m/s", acceleration: "5 m/s^2" };
            list.push({ move: "0.1 m", velocity: last.velocity, acceleration: last.acceleration });
            renderForms();
            scheduleCheck();
          },
        }, "Add move"),
        el("button", { type: "button", class: "secondary", onclick: () => { list.push({ dwell: "0.2 s" }); renderForms(); scheduleCheck(); } }, "Add dwell")),
    ];
  }
  return [type, numbers, segments, el("div", { class: "profile-plot", id: `profile-plot-${i}`, "data-stage": String(i) })];
}

// Draw each stage's sampled profile (the service's) into its place in the form.
function drawProfiles() {
  if (!view) return;
  view.stages.forEach((st, i) => {
    const node = document.getElementById(`profile-plot-${i}`);
    if (!node || !st.profile) return;
    const p = st.profile;
    const data = PROFILE_ROWS.map(([k, , scale], row) => ({
      x: p.time, y: p[k].map((v) => v * scale), name: k, xaxis: "x", yaxis: row ? `y${row + 1}` : "y",
      line: { color: PALETTE[row], width: 1.5 }, hovertemplate: `%{y:.4g}<extra>${k}</extra>`,
    }));
    const layout = {
      height: 300,
      margin: { t: 8, r: 10, b: 36, l: 62 },
      showlegend: false,
      xaxis: { title: { text: "time (s)", font: { size: 11 } }, anchor: "y3" },
      yaxis: { title: { text: PROFILE_ROWS[0][1], font: { size: 10 } }, domain: [0.7, 1] },
      yaxis2: { title: { text: PROFILE_ROWS[1][1], font: { size: 10 } }, domain: [0.36, 0.64] },
      yaxis3: { title: { text: PROFILE_ROWS[2][1], font: { size: 10 } }, domain: [0, 0.3] },
      shapes: [{ type: "line", xref: "x", yref: "paper", x0: p.end, x1: p.end, y0: 0, y1: 1, line: { color: "#888", width: 1, dash: "dot" } }],
    };
    Plotly.react(node, data, layout, { ...PLOT_CONFIG, displayModeBar: false });
    node.dataset.end = String(p.end);
  });
}
