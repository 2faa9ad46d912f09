// The runs list, live from the service's runs stream (sent again whenever any run changes).

import { STATUS_TEXT, ago, controlPending, escapeHtml, of, shownStatus } from "./format.js";

export function renderRuns(body, runs, selected) {
  if (!runs.length) {
    body.innerHTML = '<tr><td colspan="8" class="muted">no runs yet</td></tr>';
    return;
  }
  body.innerHTML = runs.map((r) => `
    <tr data-run-id="${r.id}" class="${r.id === selected ? "selected" : ""}">
      <td>#${r.id}</td>
      <td><span class="status ${shownStatus(r)}">${STATUS_TEXT[shownStatus(r)] ?? escapeHtml(r.status)}</span>${
        controlPending(r) ? ` <span class="muted">(${r.control} requested)</span>` : ""}</td>
      <td>${escapeHtml(r.env)}</td><td>${escapeHtml(r.task)}</td>
      <td>${escapeHtml(r.method)}${r.preset ? ` <span class="muted">${escapeHtml(r.preset)}</span>` : ""}</td>
      <td>${of(r.epoch, r.epochs_total)}</td>
      <td>${of(r.n_labels, r.n_total)}</td>
      <td class="since" data-time="${r.last_label_at ?? ""}">${ago(r.last_label_at)}</td>
    </tr>`).join("");
}

// "12 s ago" cells tick without a re-render.
export function tickTimes(root = document) {
  for (const cell of root.querySelectorAll(".since[data-time]")) cell.textContent = ago(cell.dataset.time || null);
}
