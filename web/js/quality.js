// A run's labeler quality control (operator token): redundancy r and the gold rate. The service
// judges the values; a refusal is shown, never hidden.

import { api } from "./api.js";

export class QualityForm {
  constructor(root, onChange) {
    this.form = root.querySelector("#quality");
    this.redundancy = root.querySelector("#quality-redundancy");
    this.gold = root.querySelector("#quality-gold");
    this.message = root.querySelector("#quality-message");
    this.onChange = onChange;
    this.runId = null;
    this.form.addEventListener("submit", (event) => {
      event.preventDefault();
      this.apply();
    });
  }

  show(run) {
    const editing = this.form.contains(document.activeElement) && this.runId === run.id;
    this.runId = run.id;
    this.form.dataset.redundancy = String(run.redundancy);
    this.form.dataset.goldRate = String(run.gold_rate);
    if (!editing) {
      this.redundancy.value = String(run.redundancy);
      this.gold.value = String(Math.round(100 * run.gold_rate));
    }
    const over = run.status === "finished" || run.status === "failed";
    for (const input of this.form.querySelectorAll("input, button")) input.disabled = over;
  }

  async apply() {
    this.message.textContent = "";
    const body = { redundancy: Number(this.redundancy.value), gold_rate: Number(this.gold.value) / 100 };
    try {
      const run = await api(`runs/${this.runId}/quality`, { method: "PUT", body });
      this.onChange(run);
    } catch (error) {
      this.message.textContent = error.message;
    }
  }
}
