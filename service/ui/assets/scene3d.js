// /ui/scene: the machine in 3D (plotly's 3D traces): the base, its mounts at their corners, the stages at
// home with the line each travels along, the points of interest and the c.g., all placed from what the
// service computed (POST /scenes/check). The base moves as a rigid body: a mode shape animated, or the
// motion of a run played back, larger by an exaggeration factor; the mounts stretch between the floor and
// the base.
"use strict";

const MODE_PERIOD_S = 1.6; // one cycle of an animated mode on the screen
const MODE_REACH_M = 0.002; // the far mount of an animated mode moves by this much times the exaggeration
const BOX_EDGES = [[0, 1], [1, 2], [2, 3], [3, 0], [4, 5], [5, 6], [6, 7], [7, 4], [0, 4], [1, 5], [2, 6], [3, 7]];

const Scene3D = {
  node: null,
  geometry: null, // rest positions, from the service's view of the scene
  ranges: null,
  modeTimer: null,

  // The rigid motion q = [x, y, z, rx, ry, rz] (m, rad) of the base about its c.g. applied to point p.
  moved(p, q) {
    const g = this.geometry.cg;
    const r = [p[0] - g[0], p[1] - g[1], p[2] - g[2]];
    const th = [q[3], q[4], q[5]];
    const a = Math.hypot(...th);
    let rr = r;
    if (a > 0) {
      // Rodrigues: r cos a + (k x r) sin a + k (k . r)(1 - cos a)
      const k = th.map((v) => v / a);
      const kxr = [k[1] * r[2] - k[2] * r[1], k[2] * r[0] - k[0] * r[2], k[0] * r[1] - k[1] * r[0]];
      const kr = k[0] * r[0] + k[1] * r[1] + k[2] * r[2];
      const c = Math.cos(a);
      const s = Math.sin(a);
      rr = [0, 1, 2].map((i) => r[i] * c + kxr[i] * s + k[i] * kr * (1 - c));
    }
    return [g[0] + q[0] + rr[0], g[1] + q[1] + rr[1], g[2] + q[2] + rr[2]];
  },

  // Stage positions along their axes (m, by name) -> the offset of each stage from home (its parents' too).
  stageOffset(stage, along) {
    const off = [0, 0, 0];
    const byName = Object.fromEntries(this.geometry.stages.map((s) => [s.name, s]));
    let st = stage;
    for (let depth = 0; st && depth < 10; depth++) {
      const s = (along && along[st.name]) || 0;
      for (let i = 0; i < 3; i++) off[i] += st.axis[i] * s;
      st = st.parent ? byName[st.parent] : null;
    }
    return off;
  },

  setView(view) {
    const b = view.base;
    const [cx, cy, cz] = b.box_corner;
    const [lx, ly, lz] = b.box_size;
    const corners = [
      [cx, cy, cz], [cx + lx, cy, cz], [cx + lx, cy + ly, cz], [cx, cy + ly, cz],
      [cx, cy, cz + lz], [cx + lx, cy, cz + lz], [cx + lx, cy + ly, cz + lz], [cx, cy + ly, cz + lz],
    ];
    const spring = Math.max(0.08, 0.3 * lz);
    const mounts = view.mounts.map((m) => ({
      label: `${m.name} (${m.place})`,
      top: m.position,
      floor: [m.position[0], m.position[1], m.position[2] - spring],
      seat: [m.position[0], m.position[1], Math.max(m.position[2], cz)],
    }));
    this.geometry = {
      cg: b.cg,
      corners,
      mounts,
      stages: view.stages,
      points: Object.entries(view.points).map(([name, p]) => ({ name, p })),
    };
    const all = [...corners, ...mounts.map((m) => m.floor), ...view.stages.flatMap((s) => s.travel_ends), ...Object.values(view.points)];
    const lo = [0, 1, 2].map((i) => Math.min(...all.map((p) => p[i])));
    const hi = [0, 1, 2].map((i) => Math.max(...all.map((p) => p[i])));
    const span = Math.max(...[0, 1, 2].map((i) => hi[i] - lo[i]), 0.1);
    const pad = 0.15 * span;
    this.ranges = [0, 1, 2].map((i) => [lo[i] - pad, hi[i] + pad]);
    this.pose([0, 0, 0, 0, 0, 0], null);
  },

  traces(q, along) {
    const G = this.geometry;
    const mv = (p) => this.moved(p, q);
    const corners = G.corners.map(mv);
    const col = (pts, i) => pts.map((p) => (p ? p[i] : null));
    const path = (segments) => segments.flatMap((s) => [...s, null]);
    const edges = path(BOX_EDGES.map(([a, b]) => [corners[a], corners[b]]));
    const springs = path(G.mounts.map((m) => [m.floor, mv(m.top)]));
    const seats = path(G.mounts.map((m) => [mv(m.top), mv(m.seat)]));
    const tops = G.mounts.map((m) => mv(m.top));
    const stageAt = G.stages.map((s) => {
      const off = this.stageOffset(s, along);
      return mv([s.home[0] + off[0], s.home[1] + off[1], s.home[2] + off[2]]);
    });
    const travel = path(
      G.stages.map((s) => {
        const parent = s.parent ? G.stages.find((t) => t.name === s.parent) : null;
        const off = parent ? this.stageOffset(parent, along) : [0, 0, 0];
        return s.travel_ends.map((e) => mv([e[0] + off[0], e[1] + off[1], e[2] + off[2]]));
      })
    );
    const points = G.points.map((pt) => mv(pt.p));
    const cg = [mv(G.cg)];
    const line = (name, pts, color, width, extra = {}) => ({
      type: "scatter3d", mode: "lines", name, x: col(pts, 0), y: col(pts, 1), z: col(pts, 2),
      line: { color, width }, hoverinfo: "skip", ...extra,
    });
    const marks = (name, pts, labels, symbol, color, size) => ({
      type: "scatter3d", mode: "markers+text", name, x: col(pts, 0), y: col(pts, 1), z: col(pts, 2),
      text: labels, textposition: "top center", marker: { symbol, color, size }, hovertemplate: "%{text}<extra></extra>",
    });
    return [
      {
        type: "mesh3d", name: "base", x: col(corners, 0), y: col(corners, 1), z: col(corners, 2),
        i: [0, 0, 4, 4, 0, 0, 1, 1, 2, 2, 3, 3], j: [1, 2, 5, 6, 1, 5, 2, 6, 3, 7, 0, 4], k: [2, 3, 6, 7, 5, 4, 6, 5, 7, 6, 4, 7],
        color: "#8d99a6", opacity: 0.35, flatshading: true, hoverinfo: "name", showlegend: true,
      },
      line("base edges", edges, "#4b5561", 3, { showlegend: false }),
      line("mounts", springs, "#d62728", 7),
      line("seats", seats, "#9aa3ad", 3, { showlegend: false }),
      marks("mount places", tops, G.mounts.map((m) => m.label), "square", "#d62728", 4),
      line("stage travel", travel, "#2ca02c", 4, { line: { color: "#2ca02c", width: 4, dash: "dash" } }),
      marks("stages", stageAt, G.stages.map((s) => `${s.name} (${fmt(s.mass, 3)} kg)`), "circle", "#2ca02c", 7),
      marks("points", points, G.points.map((p) => p.name), "diamond", "#9467bd", 5),
      marks("c.g.", cg, ["c.g."], "cross", "#1f77b4", 6),
    ];
  },

  pose(q, along) {
    if (!this.geometry) return;
    const axis = (title, range) => ({ title: { text: title }, range, autorange: false });
    const [rx, ry, rz] = this.ranges;
    const w = [rx, ry, rz].map((r) => r[1] - r[0]);
    const m = Math.max(...w);
    const layout = {
      margin: { l: 0, r: 0, t: 10, b: 0 },
      uirevision: "machine",
      legend: { x: 0, y: 1 },
      scene: {
        xaxis: axis("X (m)", rx), yaxis: axis("Y (m)", ry), zaxis: axis("Z, up (m)", rz),
        aspectmode: "manual", aspectratio: { x: w[0] / m, y: w[1] / m, z: w[2] / m },
        camera: { eye: { x: -1.3, y: -1.6, z: 0.9 } },
      },
    };
    Plotly.react(this.node, this.traces(q, along), layout, PLOT_CONFIG);
  },

  stop() {
    if (this.modeTimer) cancelAnimationFrame(this.modeTimer);
    this.modeTimer = null;
  },

  // Animate a mode: its shape (1 m at the far mount) times MODE_REACH_M times the exaggeration.
  animateMode(shape, exaggeration) {
    this.stop();
    const q = ["x", "y", "z", "rx", "ry", "rz"].map((k) => (shape[k] || 0) * MODE_REACH_M * exaggeration);
    const started = performance.now();
    const frame = (now) => {
      const s = Math.sin((2 * Math.PI * (now - started)) / 1000 / MODE_PERIOD_S);
      this.pose(q.map((v) => v * s), null);
      this.modeTimer = requestAnimationFrame(frame);
    };
    this.modeTimer = requestAnimationFrame(frame);
  },
};
