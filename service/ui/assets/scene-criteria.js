// /ui/scene: what the machine must meet (criteria at its points of interest and on its mounts) and the floor
// it stands on (a spectrum per axis: a VC curve by name or one-third-octave band levels), in units, each
// field checked by the service as typed (its 422 shown at the field, as for every other field).
"use strict";

const VC_CURVES = ["VC-A", "VC-B", "VC-C", "VC-D", "VC-E", "VC-F", "VC-G"];
const FLOOR_KINDS = [["", "still"], ["vc", "a VC curve"], ["bands", "one-third-octave bands"]];

function vcList(id) {
  return el("datalist", { id }, VC_CURVES.map((n) => el("option", { value: n })));
}

function withList(row, id) {
  for (const input of row.querySelectorAll("input")) input.setAttribute("list", id);
  return row;
}

// One-third-octave bands as typed ("4 Hz: 20 um/s, 8 Hz: 10 um/s") <-> as the scene holds them.
function bandsText(bands) {
  return bands && typeof bands === "object" ? Object.entries(bands).map(([f, v]) => `${f}: ${shown(v)}`).join(", ") : "";
}

function bandsRead(text) {
  const bands = {};
  for (const piece of text.split(",")) {
    if (!piece.trim()) continue;
    const [f, v] = piece.split(/:(.*)/s);
    bands[f.trim()] = v === undefined ? null : parsed(v) === undefined ? null : parsed(v);
  }
  return Object.keys(bands).length ? bands : undefined;
}

function criteriaForm() {
  const criteria = scene.criteria || {};
  const points = Object.keys(scene.points || {});
  const names = [...points, ...Object.keys(criteria).filter((k) => k !== "isolators" && !points.includes(k))];
  const perPoint = names.map((name) => {
    const at = (...p) => ["criteria", name, ...p];
    return section(
      `at ${name}${points.includes(name) ? "" : " (no such point)"}`,
      at(),
      field("peak displacement", [at("displacement")], "m (or 10 um)", { placeholder: "no limit" }),
      field("settle within", [at("settle", "within")], "m (or 10 um)", { placeholder: "no limit" }),
      field("… at most after", [at("settle", "after")], "s after each move", { group: at("settle") }),
      withList(field("floor velocity", [at("velocity")], "VC curve", { placeholder: "VC-A … VC-G", text: true }), "vc-curves"),
      points.includes(name)
        ? null
        : el("button", { type: "button", class: "secondary", onclick: () => { delete scene.criteria[name]; renderForms(); scheduleCheck(); } }, `Remove the criteria at ${name}`)
    );
  });
  const iso = ["criteria", "isolators"];
  const liftoff = el("input", {
    type: "checkbox", id: "no-liftoff", "data-path": key([...iso, "no_liftoff"]), checked: Boolean(getAt(scene, [...iso, "no_liftoff"])),
    onchange: (e) => { setAt(scene, [...iso, "no_liftoff"], e.target.checked ? true : undefined); scheduleCheck(); },
  });
  const liftRow = el("div", { class: "field" }, el("label", { for: "no-liftoff" }, "no lift-off"), el("div", { class: "inputs" }, liftoff, el("span", { class: "unit" }, "no mount loses its whole preload")), el("div", { class: "field-error" }));
  liftRow.errorNode = liftRow.lastChild;
  fields.set(key([...iso, "no_liftoff"]), liftRow);
  const mounts = section(
    "on every mount",
    iso,
    liftRow,
    field("largest load", [[...iso, "max_force"]], "N (or 20 kN)", { placeholder: "no limit" }),
    field("largest deflection", [[...iso, "max_deflection"]], "m (or 10 mm)", { placeholder: "no limit" })
  );
  return section(
    "Criteria",
    ["criteria"],
    vcList("vc-curves"),
    points.length ? null : el("p", { class: "muted" }, "Add points of interest to set limits at them."),
    perPoint,
    mounts
  );
}

function floorForm() {
  const floor = scene.floor || {};
  const rows = ["x", "y", "z"].map((axis) => {
    const at = ["floor", "spectrum", axis];
    const value = getAt(scene, at);
    const kind = value === undefined || value === null ? "" : typeof value === "string" ? "vc" : value.bands ? "bands" : "other";
    const choose = selectField(`${axis.toUpperCase()} spectrum`, [...at, "_kind"], kind === "other" ? [...FLOOR_KINDS, ["other", "a PSD (as written)"]] : FLOOR_KINDS, (v) => {
      if (v === "vc") setAt(scene, at, "VC-D");
      else if (v === "bands") setAt(scene, at, { bands: { "4 Hz": "20 um/s", "8 Hz": "10 um/s" } });
      else if (v === "") setAt(scene, at, undefined);
      renderForms();
      scheduleCheck();
    });
    choose.querySelector("select").value = kind;
    fields.set(key(at), choose);
    let detail = null;
    if (kind === "vc") detail = withList(field(`${axis.toUpperCase()} curve`, [at], "RMS velocity per band", { text: true }), "vc-curves");
    if (kind === "bands") {
      detail = field(`${axis.toUpperCase()} bands`, [[...at, "bands"]], "centre: RMS velocity, …", {
        read: bandsRead, show: bandsText, placeholder: "4 Hz: 20 um/s, 8 Hz: 10 um/s",
      });
    }
    return [choose, detail];
  });
  const others = ["sine", "recorded"].filter((k) => floor[k]);
  return section(
    "Floor",
    ["floor"],
    el("p", { class: "muted" }, "The floor's steady vibration under the mounts, per axis (what a velocity criterion judges)."),
    rows,
    others.length ? el("p", { class: "muted" }, `The floor also moves by a ${others.join(" and ")} as written in the scene.`) : null
  );
}
