// The labeling panel: queue health, pace, per-labeler counts and median seconds per label, and
// agreement with the oracle (the task rule, exact) where the task can judge, and agreement between
// labelers (no rule needed) where two or more label the same segment.

import { ago, escapeHtml, num, of, percent } from "./format.js";

// `ruleless`: the run has no task rule (only an instruction), so there is no oracle to agree with.
export function renderLabeling(element, view, ruleless = false) {
  const s = view.labeling;
  const rows = s.labelers.map((l) => `<tr>
      <td>${escapeHtml(l.name)}</td><td>${l.labels}</td><td>${l.skips}</td>
      <td>${l.median_s == null ? "—" : `${num(l.median_s, 1)} s`}</td><td>${percent(l.agreement)}</td>
    </tr>`).join("");
  element.innerHTML = `
    <dl>
      <dt>queue</dt>
      <dd><span id="q-pending">${s.queue.pending}</span> pending · <span id="q-leased">${s.queue.leased}</span> leased ·
          <span id="q-labelled">${s.queue.labelled}</span> labelled${s.queue.retired ? ` · ${s.queue.retired} retired` : ""}</dd>
      <dt>labels</dt><dd>${of(s.n_labels, s.n_total)}</dd>
      <dt>pace</dt><dd>${num(s.labels_per_min, 1)} labels / min (last 5 min)</dd>
      <dt>last label</dt><dd data-time="${s.last_label_at ?? ""}" class="since">${ago(s.last_label_at)}</dd>
      <dt>oracle agrees</dt>
      <dd>${ruleless ? "no task rule (instruction only)" : s.judged ? `${percent(s.agreement)} of ${s.judged} labels` : "nothing to judge yet"}</dd>
      <dt>labelers agree</dt>
      <dd id="between-labelers">${s.shared_queries ? `${percent(s.between_labelers)} on ${s.shared_queries} shared segments` : "no segment labelled by two yet"}</dd>
    </dl>
    ${rows ? `<table><thead><tr><th>labeler</th><th>labels</th><th>skips</th><th>median</th><th>oracle agrees</th></tr></thead>
      <tbody>${rows}</tbody></table>` : '<p class="muted">no labelers yet</p>'}`;
}
