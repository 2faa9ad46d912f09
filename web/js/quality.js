// A run's labeler quality control (operator token): redundancy r and the gold rate. An input shows
// the run's value until the operator types in it; Apply sends only what was typed (another
// operator's change to the other field stands), checks it first, and says what it did.

import { api } from "./api.js";

const FIELDS = {
  redundancy: { min: 1, max: 10, what: "redundancy: a whole number of labels per query, 1 to 10" },
  gold: { min: 0, max: 50, what: "gold: a whole percentage, 0 to 50" },
};

export class QualityForm {
  constructor(root, onChange) {
    this.form = root.querySelector("#quality");
    this.inputs = { redundancy: root.querySelector("#quality-redundancy"), gold: root.querySelector("#quality-gold") };
    this.message = root.querySelector("#quality-message");
    this.onChange = onChange;
    this.runId = null;
    for (const input of Object.values(this.inputs)) {
      input.addEventListener("input", () => (input.dataset.typed = "1"));
    }
    this.form.addEventListener("submit", (event) => {
      event.preventDefault();
      this.apply();
    });
  }

  show(run) {
    if (this.runId !== run.id) this.forget();
    this.runId = run.id;
    this.form.dataset.redundancy = String(run.redundancy);
    this.form.dataset.goldRate = String(run.gold_rate);
    const shown = { redundancy: String(run.redundancy), gold: String(Math.round(100 * run.gold_rate)) };
    for (const [name, input] of Object.entries(this.inputs)) {
      if (!input.dataset.typed) input.value = shown[name];
    }
    const over = run.status === "finished" || run.status === "failed";
    for (const input of this.form.querySelectorAll("input, button")) input.disabled = over;
  }

  forget() {
    for (const input of Object.values(this.inputs)) delete input.dataset.typed;
  }

  say(text, ok = false) {
    this.message.textContent = text;
    this.message.classList.toggle("error", !ok);
  }

  async apply() {
    const body = {};
    for (const [name, input] of Object.entries(this.inputs)) {
      if (!input.dataset.typed) continue;
      const value = Number(input.value.trim());
      const { min, max, what } = FIELDS[name];
      if (input.value.trim() === "" || !Number.isInteger(value) || value < min || value > max) {
        this.say(what);
        input.focus();
        return;
      }
      if (name === "redundancy") body.redundancy = value;
      else body.gold_rate = value / 100;
    }
    if (Object.keys(body).length === 0) {
      this.say("nothing changed", true);
      return;
    }
    try {
      const run = await api(`runs/${this.runId}/quality`, { method: "PUT", body });
      this.forget();
      this.say("applied", true);
      this.onChange(run);
    } catch (error) {
      this.say(error.message);
    }
  }
}
