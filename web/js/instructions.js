// A run's instructions for its labelers (operator token): free text the labeling UI shows with the
// task ("From your operator: …"). The field shows the run's text until the operator types in it;
// Send stores it (empty: none), and open labeling tabs show it with their next segment (or within
// their lease renewal, 20 s). Not on the run's stream: another operator's change shows on reopening.

import { api } from "./api.js";
import { isClosed } from "./format.js";

const MAX_CHARS = 4000; // collie/schemas.py MAX_INSTRUCTIONS

export class InstructionsForm {
  constructor(root, onChange) {
    this.form = root.querySelector("#instructions");
    this.text = root.querySelector("#instructions-text");
    this.message = root.querySelector("#instructions-message");
    this.onChange = onChange;
    this.runId = null;
    this.text.addEventListener("input", () => (this.text.dataset.typed = "1"));
    this.form.addEventListener("submit", (event) => {
      event.preventDefault();
      this.apply();
    });
  }

  show(run) {
    if (this.runId !== run.id) {
      delete this.text.dataset.typed;
      this.say("", true);
    }
    this.runId = run.id;
    if (!this.text.dataset.typed) this.text.value = run.instructions ?? "";
    // stopped or over: no labeler gets another segment of it, so nobody would read new words
    const closed = isClosed(run);
    this.text.disabled = closed;
    this.form.querySelector("button").disabled = closed;
    this.text.title = closed ? "the run takes no more labels: instructions would reach nobody" : "";
  }

  say(text, ok = false) {
    this.message.textContent = text;
    this.message.classList.toggle("error", !ok);
  }

  async apply() {
    const text = this.text.value.trim();
    if (text.length > MAX_CHARS) {
      this.say(`at most ${MAX_CHARS} characters (this is ${text.length})`);
      this.text.focus();
      return;
    }
    try {
      const run = await api(`runs/${this.runId}/instructions`, { method: "PUT", body: { text } });
      delete this.text.dataset.typed;
      this.say(text ? "sent: labelers see it with their next segment" : "removed", true);
      this.onChange(run);
    } catch (error) {
      this.say(error.message);
    }
  }
}
