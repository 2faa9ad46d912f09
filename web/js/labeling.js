// The labeling panel: queue health, pace, per-labeler counts and median seconds per label,
// agreement with the oracle (the task rule, exact) where the task can judge, agreement between
// labelers (Krippendorff's α), gold accuracy — each with a one-line explanation — and the list of
// queries where labelers or the oracle disagree, each with its path drawn over the task's regions
// and, when the labeling UI's address is known, a link that replays it in 3D there.

import { ago, escapeHtml, num, of, percent, plural } from "./format.js";
import { CLASS_COLOURS, FILL, regionPath } from "./regions.js";

// `names`: the label words in value order, as the API gives them (RunPage.labels); no copy here.
const labelTag = (v, names) => (v == null ? '<span class="muted">—</span>'
  : `<span class="label-tag" style="--c:${CLASS_COLOURS[v]}">${escapeHtml(names[v] ?? String(v))}</span>`);

const COLUMN_HELP = [
  ["labels", "queries they hold a label on now: a revision replaces their label, an undo withdraws it"],
  ["skips", "segments they passed on (not labels)"],
  ["median", "median seconds per label"],
  ["oracle agrees", "share of their labels the task rule gives too"],
  ["α", "Krippendorff's α of their labels against the other labelers' on the same queries"],
  ["gold", "gold segments (the rule knows the answer, never sent to the trainer) they labelled right / labelled"],
  ["discard labels", "withdraw every label they gave in this run (the trainer drops them; the segments go back to the queue for others)"],
];

// A labeler's labels in this run can be discarded (operator; a second click confirms: `discard.armed`
// is the id of the labeler whose button waits for it, `discard.message` says what the last one did),
// until the run is stopped or over (`discard.closed`: the service keeps its labels as they are then).
const discardButton = (l, armed, closed) => (l.labels && !closed ? `<button type="button" class="danger operator-only" data-discard="${l.id}">${
  armed === l.id ? `Confirm: discard ${l.labels}` : "Discard labels"}</button>` : "");

// `ruleless`: the run has no task rule (only an instruction), so there is no oracle to agree with.
export function renderLabeling(element, view, ruleless = false, discard = { armed: null, message: "" }) {
  const s = view.labeling;
  const rows = s.labelers.map((l) => `<tr data-labeler="${escapeHtml(l.name)}">
      <td>${escapeHtml(l.name)}</td><td class="labels">${l.labels}</td><td>${l.skips}</td>
      <td>${l.median_s == null ? "—" : `${num(l.median_s, 1)} s`}</td><td>${percent(l.agreement)}</td>
      <td>${l.alpha == null ? "—" : num(l.alpha, 2)}</td>
      <td>${l.gold_answered ? `${percent(l.gold_accuracy)} of ${l.gold_answered}` : "—"}</td>
      <td>${discardButton(l, discard.armed, discard.closed)}</td>
    </tr>`).join("");
  const quality = `${s.redundancy === 1 ? "1 label per query" : `${s.redundancy} labels per query from distinct labelers`}${
    s.gold_rate ? ` · ${percent(s.gold_rate)} gold` : ""}`;
  element.innerHTML = `
    <dl>
      <dt>queue</dt>
      <dd><span id="q-pending">${s.queue.pending}</span> pending · <span id="q-leased">${s.queue.leased}</span> leased ·
          <span id="q-labelled">${s.queue.labelled}</span> labelled${s.queue.retired ? ` · ${s.queue.retired} retired` : ""}
          <p class="explain">${discard.closed ? "the run is stopped or over: it takes no more labels, and its pending queries stay unlabelled"
            : "pending: waiting for a labeler · leased: on a labeler's screen now"} · labelled: counted${s.queue.retired ? " · retired: withdrawn by the trainer" : ""}</p></dd>
      <dt>labels</dt><dd id="m-labels">${of(s.n_labels, s.n_total)}
          <p class="explain">queries whose label counts (the trainer has it)${s.n_total == null ? "" : " / the run's label budget"}</p></dd>
      <dt>quality</dt><dd id="m-quality">${quality}
          <p class="explain">a query counts once its labels are in: the majority, a tie going to the safer label (bad, then neutral)</p></dd>
      <dt>pace</dt><dd>${plural(num(s.labels_per_min, 1), "label")} / min
          <p class="explain">labels submitted in the last 5 minutes, per minute</p></dd>
      <dt>last label</dt><dd><span data-time="${s.last_label_at ?? ""}" class="since">${ago(s.last_label_at)}</span>
          <p class="explain">when the latest label arrived</p></dd>
      <dt>oracle agrees</dt>
      <dd id="m-oracle">${ruleless ? "no task rule (instruction only)" : s.judged ? `${percent(s.agreement)} of ${plural(s.judged, "label")}` : "nothing to judge yet"}
          <p class="explain">share of counted labels the task rule gives too, where the rule can judge</p></dd>
      <dt>labelers agree</dt>
      <dd id="m-alpha">${s.alpha == null ? (s.alpha_queries ? "α undefined (every label the same)" : "no query with two labels yet")
        : `α = ${num(s.alpha, 2)} on ${plural(s.alpha_queries, "query", "queries")}`}
          <p class="explain">Krippendorff's α on queries with two labels or more: 1 full agreement, 0 what chance gives, below 0 worse</p></dd>
      <dt>labeler pairs agree</dt>
      <dd id="between-labelers">${s.shared_queries ? `${percent(s.between_labelers)} on ${plural(s.shared_queries, "shared segment")}` : "no segment labelled by two yet"}
          <p class="explain">share of labeler pairs that gave the same label (needs no rule)</p></dd>
    </dl>
    ${rows ? `<table id="labelers-stats"><thead><tr><th>labeler</th><th>labels</th><th>skips</th><th>median</th><th>oracle agrees</th><th>α</th><th>gold</th><th></th></tr></thead>
      <tbody>${rows}</tbody></table>
      <p id="discard-message" class="message">${escapeHtml(discard.message)}</p>
      <ul class="explain-list">${COLUMN_HELP.map(([k, v]) => `<li><b>${k}</b>: ${v}</li>`).join("")}</ul>`
    : '<p class="muted">no labelers yet</p>'}`;
}

// A small path view of one segment in data coordinates (y up), over the task's regions.
export function pathSvg(xy, task, size = [132, 88]) {
  if (!xy.length) return '<span class="muted">no path</span>';
  const xs = xy.map((p) => p[0]);
  const ys = xy.map((p) => p[1]);
  const [w, h] = size;
  const span = Math.max(0.5, Math.max(...xs) - Math.min(...xs), (Math.max(...ys) - Math.min(...ys)) * (w / h));
  const cx = (Math.max(...xs) + Math.min(...xs)) / 2;
  const cy = (Math.max(...ys) + Math.min(...ys)) / 2;
  const scale = w / (1.6 * span);
  const view = { x0: cx - w / (2 * scale), x1: cx + w / (2 * scale), y0: cy - h / (2 * scale), y1: cy + h / (2 * scale) };
  const box = { x0: view.x0 - span, x1: view.x1 + span, y0: view.y0 - span, y1: view.y1 + span };
  const regions = task ? [
    `<rect x="${box.x0}" y="${box.y0}" width="${box.x1 - box.x0}" height="${box.y1 - box.y0}" fill="${FILL[task.background]}"/>`,
    ...task.regions.map((r) => regionPath(r, box, false)).map((d, i) => (d
      ? `<path d="${d}" fill="${FILL[task.regions[i].desirability]}" fill-rule="evenodd"/>` : "")),
  ].join("") : "";
  const points = xy.map(([x, y]) => `${x},${y}`).join(" ");
  const [sx, sy] = xy[0];
  const [ex, ey] = xy[xy.length - 1];
  const dot = (x, y, r, fill) => `<circle cx="${x}" cy="${y}" r="${r / scale}" fill="${fill}"/>`;
  return `<svg class="path-view" width="${w}" height="${h}" viewBox="0 0 ${w} ${h}" role="img" aria-label="path of the segment">
    <g transform="matrix(${scale} 0 0 ${-scale} ${-view.x0 * scale} ${view.y1 * scale})">${regions}
      <polyline points="${points}" fill="none" stroke="#1d2330" stroke-width="1.6" vector-effect="non-scaling-stroke"/>
      ${dot(sx, sy, 3.2, "#1d2330")}${dot(ex, ey, 3.2, "#2563eb")}
    </g></svg>`;
}

// `replayHref(queryId)`: the labeling UI's review of that query (run.js), or null without a UI address.
export function renderDisagreements(element, count, view, task, names, replayHref = null) {
  const s = view.labeling;
  count.textContent = s.n_disagreements ? `(${s.n_disagreements}${s.n_disagreements > s.disagreements.length ? `, newest ${s.disagreements.length} shown` : ""})` : "";
  if (!s.disagreements.length) {
    const why = !s.n_labels ? "nothing labelled yet"
      : task ? "every labelled query has agreeing labels" : "labelers agree on every shared query (no task rule to judge by)";
    element.innerHTML = `<p class="muted">none: ${why}</p>`;
    return;
  }
  element.innerHTML = `<table><thead><tr><th>query</th><th>session</th><th>labels</th><th>counts as</th><th>oracle</th><th>path</th>${replayHref ? "<th>3D</th>" : ""}</tr></thead><tbody>
    ${s.disagreements.map((d) => `<tr data-query="${escapeHtml(d.query_id)}">
      <td>${escapeHtml(d.query_id)}</td><td>${d.session}</td>
      <td>${Object.entries(d.labels).map(([who, v]) => `${escapeHtml(who)} ${labelTag(v, names)}`).join("<br>")}</td>
      <td>${d.effective == null ? '<span class="muted">not yet</span>' : labelTag(d.effective, names)}</td>
      <td>${labelTag(d.oracle, names)}</td><td>${pathSvg(d.xy, task)}</td>${replayHref
        ? `<td><a class="replay-3d" href="${escapeHtml(replayHref(d.query_id))}" target="_blank" rel="noopener">replay in 3D</a></td>` : ""}</tr>`).join("")}
  </tbody></table>`;
}
