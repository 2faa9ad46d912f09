// The skill map: the latest evaluation's trajectories over the task's regions, the labelled
// states coloured by label, and optionally the guidance w(s) along the trajectories. 2-D robots
// are drawn in x-y; 1-D ones (HalfCheetah: y is always 0) as x over time.

import { NARROW_PX, plot } from "./plotly.js";
import { CLASS_COLOURS, FILL, regionPath, regionShapes, undrawn } from "./regions.js";

const LABEL_SYMBOLS = ["x", "circle", "diamond"]; // by label value (0 bad, 1 neutral, 2 good)
const STATE_SIZE = 5; // a labelled segment's states
const END_SIZE = 11; // its last state: large enough to show the class's shape
const W_SCALE = [[0, CLASS_COLOURS[0]], [0.5, CLASS_COLOURS[1]], [1, CLASS_COLOURS[2]]]; // w ∈ [0, 2]

// One colour per skill: its direction for 2-D skills (as METRA's plots), else its index.
function skillColour(skill, i, n) {
  const angle = skill.length === 2 ? Math.atan2(skill[1], skill[0]) : (2 * Math.PI * i) / Math.max(n, 1);
  const hue = Math.round(((angle * 180) / Math.PI + 360) % 360);
  return `hsl(${hue}, 70%, 42%)`;
}

function bounds(paths, oneD) {
  let x0 = Infinity, x1 = -Infinity, y0 = Infinity, y1 = -Infinity;
  for (const p of paths) {
    for (let i = 0; i < p.length; i++) {
      const x = p[i][0];
      const y = oneD ? i : p[i][1];
      if (x < x0) x0 = x;
      if (x > x1) x1 = x;
      if (y < y0) y0 = y;
      if (y > y1) y1 = y;
    }
  }
  if (!Number.isFinite(x0)) return { x: [-10, 10], y: [-10, 10] };
  if (oneD) {
    const pad = Math.max(1, 0.08 * (x1 - x0));
    return { x: [x0 - pad, x1 + pad], y: [y0, y1 || 1] };
  }
  const half = Math.max(1, 0.55 * Math.max(x1 - x0, y1 - y0));
  const cx = (x0 + x1) / 2;
  const cy = (y0 + y1) / 2;
  return { x: [cx - half, cx + half], y: [cy - half, cy + half] };
}

export class SkillMap {
  constructor(element, note) {
    this.element = element;
    this.note = note;
    this.task = null;
    this.rollouts = null;
    this.labelled = [];
    this.labels = []; // [{value, name}] from the service (RunDashboard.labels)
    this.colourBy = "skill";
    this.oneD = false;
  }

  set({ task, rollouts, labelled, labels, colourBy, env }) {
    if (task !== undefined) this.task = task;
    if (labels !== undefined) this.labels = labels;
    if (rollouts !== undefined) this.rollouts = rollouts;
    if (labelled !== undefined) this.labelled = labelled;
    if (colourBy !== undefined) this.colourBy = colourBy;
    if (env !== undefined) this.env = env;
    const paths = (this.rollouts?.rollouts ?? []).map((r) => r.xy);
    this.oneD = this.env === "half_cheetah" || (paths.length > 0 && paths.every((p) => p.every((q) => q[1] === 0)));
    return this.render();
  }

  trajectoryTraces(rollouts) {
    const at = (xy, i) => (this.oneD ? [xy[i][0], i] : xy[i]);
    const coords = (r) => r.xy.map((_, i) => at(r.xy, i));
    const hasW = rollouts.some((r) => Array.isArray(r.extra?.w));
    if (this.colourBy === "w" && hasW) {
      const x = [], y = [], w = [];
      for (const r of rollouts) {
        coords(r).forEach(([px, py], i) => { x.push(px); y.push(py); w.push(r.extra.w?.[i] ?? null); });
        x.push(null); y.push(null); w.push(null);
      }
      return [{
        type: "scatter", mode: "lines+markers", x, y, name: "w(s)", showlegend: false, hoverinfo: "skip",
        line: { color: "rgba(60,60,60,0.25)", width: 1 },
        marker: { size: 4, color: w, cmin: 0, cmax: 2, colorscale: W_SCALE, colorbar: { title: { text: "w(s)" }, thickness: 12 } },
      }];
    }
    return rollouts.map((r, i) => {
      const xy = coords(r);
      return {
        type: "scatter", mode: "lines", x: xy.map((p) => p[0]), y: xy.map((p) => p[1]),
        name: `skill ${i}`, showlegend: false, hovertemplate: `skill ${i}<br>%{x:.2f}, %{y:.2f}<extra></extra>`,
        line: { color: skillColour(r.skill, i, rollouts.length), width: 1.6 },
      };
    });
  }

  labelledTraces() {
    if (this.oneD) return [];
    return this.labels.map(({ value: label, name }) => {
      const segments = this.labelled.filter((s) => s.label === label);
      const x = [], y = [], size = [];
      for (const s of segments) {
        s.xy.forEach(([px, py], i) => { x.push(px); y.push(py); size.push(i === s.xy.length - 1 ? END_SIZE : STATE_SIZE); });
        x.push(null); y.push(null); size.push(0); // a gap: segments are not joined to each other
      }
      // Each segment a thick line of its class's colour through small markers, ending in a large
      // one of its class's shape (bad and neutral told apart at a glance, colour-blind too). No dark
      // outline: on 20 overlapping states it drew a black smear that hid the colour.
      return {
        type: "scatter", mode: "lines+markers", x, y, name: `labelled ${name} (${segments.length})`,
        visible: segments.length ? true : "legendonly", hoverinfo: "name", connectgaps: false,
        line: { color: CLASS_COLOURS[label], width: 3 },
        marker: { size, symbol: LABEL_SYMBOLS[label], color: CLASS_COLOURS[label], line: { width: 0 } },
      };
    });
  }

  // Legend-only entries (no data): what the lines and the shading mean.
  legendTraces(rollouts) {
    const entry = (name, marker, mode = "markers") => ({ type: "scatter", mode, x: [null], y: [null], name, hoverinfo: "skip", marker, legendgroup: name });
    const entries = [];
    if (rollouts.length) {
      const byW = this.colourBy === "w" && rollouts.some((r) => Array.isArray(r.extra?.w));
      entries.push({ ...entry(byW ? "trajectories, coloured by w(s)" : `evaluation trajectories (${rollouts.length}), one colour per skill`,
        {}, "lines"), line: { color: byW ? "#888" : skillColour([1, 0], 0, 1), width: 2 } });
    }
    if (this.task && !this.oneD) {
      const box = { x0: -1, x1: 1, y0: -1, y1: 1 }; // only whether a region is drawn at all matters here
      const drawn = this.task.regions.filter((r) => regionPath(r, box, false) != null);
      const classes = new Set([this.task.background, ...drawn.map((r) => r.desirability)]);
      for (const { value: c, name } of this.labels) {
        if (classes.has(c)) entries.push(entry(`${name} region`, { symbol: "square", size: 12, color: FILL[c], line: { width: 1, color: "#999" } }));
      }
    }
    return entries;
  }

  render() {
    const rollouts = this.rollouts?.rollouts ?? [];
    const view = bounds([...rollouts.map((r) => r.xy), ...(this.oneD ? [] : this.labelled.map((s) => s.xy))], this.oneD);
    const traces = [...this.trajectoryTraces(rollouts), ...this.labelledTraces(), ...this.legendTraces(rollouts)];
    const layout = {
      margin: { l: 45, r: 10, t: 10, b: 40 },
      xaxis: { range: view.x, title: { text: "x" }, zeroline: false },
      yaxis: { range: view.y, title: { text: this.oneD ? "time (samples along the episode)" : "y" }, zeroline: false,
        ...(this.oneD ? {} : { scaleanchor: "x", scaleratio: 1 }) },
      shapes: regionShapes(this.task, view, this.oneD),
      legend: { orientation: "h", y: this.element.clientWidth < NARROW_PX ? -0.2 : -0.12 }, // a phone's wraps: below the x title
      uirevision: "map",
      plot_bgcolor: "#fff",
    };
    const notes = undrawn(this.task, this.oneD);
    if (this.colourBy === "w" && rollouts.length && !rollouts.some((r) => Array.isArray(r.extra?.w))) {
      notes.push("no w(s) in this evaluation (w ≡ 1 until guidance starts, or the method has none)");
    }
    this.note.textContent = notes.join(" · ");
    const title = this.element.closest("figure")?.querySelector("#map-title");
    if (title) { // the evaluation shown is the last one, a few epochs behind the run's counter
      title.textContent = this.rollouts ? `skills · evaluation at epoch ${this.rollouts.epoch}` : "skills · no evaluation yet";
    }
    return plot(this.element, traces, layout).then(() => {
      this.element.dataset.epoch = this.rollouts ? String(this.rollouts.epoch) : "";
      this.element.dataset.trajectories = String(rollouts.length);
      this.element.dataset.labelled = String(this.labelled.length);
      this.element.dataset.renderedAt = String(Date.now());
    });
  }
}
