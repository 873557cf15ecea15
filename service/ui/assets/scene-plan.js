// /ui/scene: the plan view (the machine from above, plotly 2D): the base's outline, each mount where it
// stands with its name and corner, the c.g., each stage's travel and the points of interest, all from the
// service's view of the scene (POST /scenes/check). A mount is a circle that can be dragged to a new place:
// the scene then lists its mounts one by one (the layout's four become a list) with the new position; the
// layout helper lays four out around the c.g. again.
"use strict";

const MOUNT_RADIUS_SHARE = 0.025; // a mount's circle, as a share of the base's larger side

const ScenePlan = {
  node: null,
  onMove: null, // (mount index, [x, y] in m) -> void: a mount dragged to a new place

  draw(view) {
    const b = view.base;
    const [cx, cy] = b.box_corner;
    const [lx, ly] = b.box_size;
    const r = MOUNT_RADIUS_SHARE * Math.max(lx, ly);
    const outline = {
      x: [cx, cx + lx, cx + lx, cx, cx], y: [cy, cy, cy + ly, cy + ly, cy], mode: "lines", name: "base",
      line: { color: "#555", width: 2 }, fill: "toself", fillcolor: "rgba(160,160,160,0.15)", hoverinfo: "skip",
    };
    const mounts = {
      // an invisible marker as wide as the circle keeps each name clear of it: front mounts named below, back ones above
      x: view.mounts.map((m) => m.position[0]), y: view.mounts.map((m) => m.position[1]), mode: "markers+text", name: "mounts",
      marker: { size: 26, color: "rgba(0,0,0,0)" },
      text: view.mounts.map((m) => `${m.name} (${m.place})`), textfont: { size: 11, color: "#1f4e79" },
      textposition: view.mounts.map((m) => (m.place.startsWith("back") ? "top center" : "bottom center")),
      hovertemplate: "%{text}<br>x %{x:.4g} m, y %{y:.4g} m<extra></extra>",
    };
    const travel = { x: [], y: [], mode: "lines", name: "stage travel", line: { color: "#d62728", width: 3 }, hoverinfo: "skip" };
    for (const s of view.stages) {
      travel.x.push(s.travel_ends[0][0], s.travel_ends[1][0], null);
      travel.y.push(s.travel_ends[0][1], s.travel_ends[1][1], null);
    }
    const stages = {
      x: view.stages.map((s) => s.home[0]), y: view.stages.map((s) => s.home[1]), mode: "markers+text", name: "stages at home",
      text: view.stages.map((s) => s.name), textposition: "top right", marker: { symbol: "square", size: 10, color: "#d62728" },
      hovertemplate: "stage %{text} at home<br>x %{x:.4g} m, y %{y:.4g} m<extra></extra>",
    };
    const names = Object.keys(view.points);
    const points = {
      x: names.map((n) => view.points[n][0]), y: names.map((n) => view.points[n][1]), mode: "markers+text", name: "points",
      text: names, textposition: "top left", marker: { symbol: "diamond", size: 9, color: "#9467bd" },
      hovertemplate: "%{text}<br>x %{x:.4g} m, y %{y:.4g} m<extra></extra>",
    };
    const cg = {
      x: [b.cg[0]], y: [b.cg[1]], mode: "markers+text", name: "c.g.", text: ["c.g."], textposition: "top center",
      marker: { symbol: "circle-cross-open", size: 14, color: "#000", line: { width: 2 } },
      hovertemplate: "c.g. of the base<br>x %{x:.4g} m, y %{y:.4g} m<extra></extra>",
    };
    const shapes = view.mounts.map((m) => ({
      type: "circle", xref: "x", yref: "y", editable: true,
      x0: m.position[0] - r, x1: m.position[0] + r, y0: m.position[1] - r, y1: m.position[1] + r,
      line: { color: "#1f4e79", width: 2 }, fillcolor: "rgba(74,144,217,0.45)",
    }));
    const pad = 0.12 * Math.max(lx, ly);
    const layout = {
      height: 420,
      margin: { t: 10, r: 10, b: 44, l: 56 },
      xaxis: { title: { text: "X (m), left to right" }, range: [cx - pad, cx + lx + pad], zeroline: false },
      yaxis: { title: { text: "Y (m), front to back" }, range: [cy - pad, cy + ly + pad], scaleanchor: "x", zeroline: false },
      shapes,
      legend: { orientation: "h", y: -0.16 },
      dragmode: false,
    };
    this.radius = r;
    Plotly.react(this.node, [outline, mounts, travel, stages, points, cg], layout, { ...PLOT_CONFIG, edits: { shapePosition: true } });
    if (!this.node.dataset.listening) {
      this.node.dataset.listening = "1";
      this.node.on("plotly_relayout", (change) => this.moved(change));
    }
  },

  // A relayout that moved shape j: its new centre, rounded to the millimetre.
  moved(change) {
    const moved = new Map();
    for (const [k, v] of Object.entries(change)) {
      const m = /^shapes\[(\d+)\]\.([xy][01])$/.exec(k);
      if (m) moved.set(Number(m[1]), { ...(moved.get(Number(m[1])) || {}), [m[2]]: v });
    }
    for (const [j, ends] of moved) {
      const shape = this.node.layout.shapes[j];
      const x = (ends.x0 !== undefined ? ends.x0 : shape.x0) + this.radius;
      const y = (ends.y0 !== undefined ? ends.y0 : shape.y0) + this.radius;
      if (this.onMove) this.onMove(j, [Math.round(x * 1000) / 1000, Math.round(y * 1000) / 1000]);
    }
  },
};

// The mounts of the scene one by one at the given places (a layout's four become a list).
function listMounts() {
  const iso = scene.isolators;
  if (!iso.list && view) {
    iso.list = view.mounts.map((m) => ({ position: m.position.map((v) => Number(v.toPrecision(6))) }));
    delete iso.layout;
  }
  return iso.list;
}

// A mount dragged on the plan view: its new x and y (m), its height kept.
function moveMount(j, xy) {
  const list = listMounts();
  if (!list || !list[j]) return;
  const z = (list[j].position || [])[2];
  list[j].position = [xy[0], xy[1], z === undefined || z === null ? view.mounts[j].position[2] : z];
  renderForms();
  scheduleCheck();
}

// The layout helper: four mounts around the c.g. again, spanning what the listed mounts span.
function layOutMounts() {
  const iso = scene.isolators;
  const pos = view.mounts.map((m) => m.position);
  const span = (i) => Math.max(...pos.map((p) => p[i])) - Math.min(...pos.map((p) => p[i]));
  const below = view.base.cg[2] - pos.reduce((sum, p) => sum + p[2], 0) / pos.length;
  iso.layout = { span_x: Number(span(0).toPrecision(6)), span_y: Number(span(1).toPrecision(6)), height: Number(below.toPrecision(6)) };
  delete iso.list;
  renderForms();
  scheduleCheck();
}
