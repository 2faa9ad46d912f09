// Training curves over epochs, in one Plotly figure of small panels. The history arrives thinned
// by the service (at most `maxPoints` rows, whatever the run's length); live rows are appended
// and the series thinned again by halves when it grows past twice that.

import { ordinal, plural } from "./format.js";
import { NARROW_PX, plot } from "./plotly.js";
import { CLASS_COLOURS } from "./regions.js";

const PANELS = [
  { title: "safe coverage", keys: ["safe_coverage"], help: "bins the skills reach outside bad regions minus the bad bins they enter (the paper's Table 1): negative when they enter more bad bins than they reach safe ones" },
  { title: "safe ratio", keys: ["safe_ratio"], help: "share of evaluation states that are not in a bad region" },
  { title: "composite coverage", keys: ["composite_coverage", "weighted_composite_coverage"], help: "good and neutral bins reached minus bad ones (weighted: good bins count twice); negative when bad bins outnumber the rest" },
  { title: "λ (Lagrange multiplier)", keys: ["lambda"], help: "METRA's multiplier of its distance constraint" },
  { title: "α (entropy)", keys: ["alpha"], log: true, help: "SAC's entropy temperature (log scale)" },
  { title: "losses", keys: ["phi_loss", "qf_loss", "policy_loss"], other: (k) => k.endsWith("_loss"), help: "training losses of the representation φ, the critics and the policy" },
  { title: "epochs / min", keys: ["epochs_per_min"], help: "training speed, wall clock between evaluations (pauses included)" },
  { title: "labels", keys: ["n_labels"], help: "labels the trainer has used so far" },
  // rule-free: what a run without a task rule (an instruction) still measures
  { title: "state coverage (visited bins)", keys: ["n_bins"], help: "bins the evaluation states visit (needs no rule)" },
  {
    title: "labels per class", keys: ["n_labels_bad", "n_labels_neutral", "n_labels_good"], help: "labels the trainer holds, by class",
    colours: { n_labels_bad: CLASS_COLOURS[0], n_labels_neutral: CLASS_COLOURS[1], n_labels_good: CLASS_COLOURS[2] }, // as on the map
  },
  { title: "guidance w(s) over evaluations", keys: ["w_mean", "w_min", "w_max"], help: "the guidance weight (Eq. 8) along the evaluation rollouts" },
];
// Two panels a row; one on a phone-wide screen, where two ran each other's titles and legends together.
const columns = (element) => (element.clientWidth && element.clientWidth < NARROW_PX ? 1 : 2);
const PALETTE = ["#2563eb", "#d97706", "#059669", "#7c3aed", "#db2777"];
const colour = (panel, name, i) => panel.colours?.[name] ?? PALETTE[i % PALETTE.length];
// A panel's second and third series are dashed and dotted: equal series (bad and neutral labels both
// 0, 2, 3) drew one line over the other, and one class seemed to have none.
const DASHES = ["solid", "dash", "dot", "dashdot"];
const GLYPHS = ["━━", "╍╍", "┉┉", "━·"];

// The epoch axis: never below 0, whole epochs as ticks while there are few. Plotly centres a single
// point in ±1 (epoch 0 ran from −1 to 1): one evaluation gets two epochs around it instead.
function epochRange(epochs) {
  if (!epochs.length) return { rangemode: "nonnegative" };
  const low = Math.min(...epochs);
  const high = Math.max(...epochs);
  // up to 6 ticks; past that Plotly steps by 1, 2, 5… of its own (it chose 0.5 for a span of 4)
  const whole = high - low <= 5 ? { tick0: 0, dtick: 1 } : {};
  if (low === high) {
    const start = Math.max(0, low - 1);
    return { ...whole, autorange: false, range: [start, start + 2] };
  }
  return { ...whole, autorange: true, rangemode: "nonnegative" };
}

export class Curves {
  constructor(element, note, maxPoints, help = null) {
    this.element = element;
    this.note = note;
    this.help = help;
    this.maxPoints = maxPoints;
    this.history = { epochs: [], created_at: [], series: {}, n_stored: 0, stride: 1 };
    this.columns = columns(element);
    window.addEventListener("resize", () => {
      if (columns(this.element) !== this.columns) this.render(); // Plotly resizes the rest itself
    });
  }

  load(history) {
    this.history = history;
    return this.render();
  }

  append(epoch, values, createdAt) {
    const h = this.history;
    const row = h.epochs.length;
    h.epochs.push(epoch);
    h.created_at.push(createdAt);
    for (const [name, value] of Object.entries(values)) {
      if (!h.series[name]) h.series[name] = new Array(row).fill(null);
      h.series[name].push(value);
    }
    for (const column of Object.values(h.series)) if (column.length === row) column.push(null);
    h.n_stored += 1;
    if (h.epochs.length > 2 * this.maxPoints) this.halve();
  }

  halve() {
    const h = this.history;
    const keep = (_, i) => i % 2 === 0 || i === h.epochs.length - 1;
    h.epochs = h.epochs.filter(keep);
    h.created_at = h.created_at.filter(keep);
    for (const name of Object.keys(h.series)) h.series[name] = h.series[name].filter(keep);
    h.stride *= 2;
  }

  // Δepochs / Δminutes between consecutive rows (wall-clock time of the posts, pauses included).
  epochsPerMinute() {
    const { epochs, created_at: t } = this.history;
    return epochs.map((e, i) => (i === 0 || t[i] <= t[i - 1] ? null : (60 * (e - epochs[i - 1])) / (t[i] - t[i - 1])));
  }

  render() {
    const h = this.history;
    const series = { ...h.series, epochs_per_min: this.epochsPerMinute() };
    const shown = (v) => v?.some((x) => x != null);
    const panels = PANELS.map((panel) => ({
      ...panel,
      names: [...panel.keys, ...(panel.other ? Object.keys(series).filter((k) => panel.other(k) && !panel.keys.includes(k)) : [])]
        .filter((k) => shown(series[k])),
    })).filter((panel) => panel.names.length); // axes without a trace would be left out of the grid
    const perRow = (this.columns = columns(this.element));
    const rows = Math.max(1, Math.ceil(panels.length / perRow));
    const epochAxis = epochRange(h.epochs);
    const traces = [];
    const layout = {
      grid: { rows, columns: perRow, pattern: "independent", ygap: 0.6, xgap: 0.12 },
      margin: { l: 55, r: 10, t: 40, b: 30 }, showlegend: false, annotations: [], uirevision: "curves",
      height: 50 + (perRow === 1 ? 205 : 175) * rows, // room for a legend of a line a name
    };
    panels.forEach((panel, p) => {
      const axis = p === 0 ? "" : String(p + 1);
      panel.names.forEach((name, i) => traces.push({
        type: "scatter", mode: h.epochs.length > 60 ? "lines" : "lines+markers", x: h.epochs, y: series[name],
        name, xaxis: `x${axis}`, yaxis: `y${axis}`, connectgaps: true, marker: { size: 4 },
        cliponaxis: false, // a point on the axis' end (epoch 0) is drawn whole
        line: { color: colour(panel, name, i), width: 1.5, dash: DASHES[i % DASHES.length] },
        hovertemplate: `${name}<br>epoch %{x}: %{y:.4g}<extra></extra>`,
      }));
      layout[`xaxis${axis}`] = { title: p >= panels.length - perRow ? { text: "epoch" } : undefined, ...epochAxis };
      layout[`yaxis${axis}`] = { type: panel.log ? "log" : "linear", exponentformat: "power" };
      // the panel's legend, under its title (one line would run into the next panel on a narrow
      // screen): each series' name in its line's colour
      // one name a line where a panel is phone-wide: three ran off its right edge
      const legend = panel.names.map((n, i) => `<span style="color:${colour(panel, n, i)}">${GLYPHS[i % GLYPHS.length]} ${n}</span>`)
        .join(perRow === 1 ? "<br>" : "  ");
      layout.annotations.push({
        text: `<b>${panel.title}</b><br>${legend}`, showarrow: false, align: "left",
        xref: `x${axis} domain`, yref: `y${axis} domain`, x: 0, y: 1.02, xanchor: "left", yanchor: "bottom",
        font: { size: 12 },
      });
    });
    if (this.help) {
      this.help.innerHTML = panels.map((p) => `<li><b>${p.title}</b>: ${p.help}</li>`).join("");
    }
    this.note.textContent = h.n_stored ? `${plural(h.n_stored, "evaluation")}${h.stride > 1 ? `, every ${ordinal(h.stride)} shown` : ""}` : "no evaluations yet";
    return plot(this.element, traces, layout).then(() => {
      this.element.dataset.points = String(h.epochs.length);
      this.element.dataset.lastEpoch = h.epochs.length ? String(h.epochs[h.epochs.length - 1]) : "";
      this.element.dataset.renderedAt = String(Date.now());
    });
  }
}
