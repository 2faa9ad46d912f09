// The runs list, live from the service's runs stream (sent again whenever any run changes).

import { STATUS_TEXT, ago, controlPending, escapeHtml, expectsTrainer, of, shownStatus } from "./format.js";

export function renderRuns(body, runs, selected) {
  if (!runs.length) {
    body.innerHTML = '<tr><td colspan="8" class="muted">no runs yet</td></tr>';
    return;
  }
  const focused = body.contains(document.activeElement) ? document.activeElement.dataset.runId : null;
  body.innerHTML = runs.map((r) => `
    <tr data-run-id="${r.id}" class="${r.id === selected ? "selected" : ""}" tabindex="0"${
      r.id === selected ? ' aria-current="true"' : ""} title="open run #${r.id} (Enter)">
      <td>#${r.id}</td>
      <td><span class="status ${shownStatus(r)}">${STATUS_TEXT[shownStatus(r)] ?? escapeHtml(r.status)}</span>${
        controlPending(r) ? ` <span class="muted">(${r.control} requested)</span>` : ""}${
        expectsTrainer(r)
          ? ` <span class="heard" data-time="${r.trainer_seen_at ?? r.created_at}"></span>` : ""}</td>
      <td>${escapeHtml(r.env)}</td><td>${escapeHtml(r.task)}</td>
      <td>${escapeHtml(r.method)}${r.preset ? ` <span class="muted">${escapeHtml(r.preset)}</span>` : ""}</td>
      <td>${of(r.epoch, r.epochs_total)}</td>
      <td>${of(r.n_labels, r.n_total)}</td>
      <td class="since" data-time="${r.last_label_at ?? ""}">${ago(r.last_label_at)}</td>
    </tr>`).join("");
  if (focused) body.querySelector(`tr[data-run-id="${focused}"]`)?.focus(); // a keyboard user keeps their place
  tickTimes(body);
}

// A live trainer calls the service every few seconds (the service notes it every 15 s): this long
// without a call, its run is said to have lost its trainer (it would wait for labels for good).
export const TRAINER_SILENT_S = 300;

// "12 s ago" cells tick without a re-render, and so does a run's word on a silent trainer.
export function tickTimes(root = document, now = Date.now()) {
  for (const cell of root.querySelectorAll(".since[data-time]")) cell.textContent = ago(cell.dataset.time || null, now);
  for (const mark of root.querySelectorAll(".heard[data-time]")) {
    const silent = (now - Date.parse(mark.dataset.time)) / 1000 > TRAINER_SILENT_S;
    mark.textContent = silent ? `no word from its trainer since ${ago(mark.dataset.time, now)}` : "";
    mark.classList.toggle("silent", silent);
  }
}
