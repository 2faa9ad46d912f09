// Run control: pause, resume, stop (operator token). Stop asks for a second click. The service is
// the judge of who may do what: a refusal (wrong token, finished run) is shown, never hidden.

import { api } from "./api.js";

export class Controls {
  constructor(root, onChange) {
    this.buttons = { pause: root.querySelector("#pause"), resume: root.querySelector("#resume"), stop: root.querySelector("#stop") };
    this.message = root.querySelector("#control-message");
    this.onChange = onChange;
    this.runId = null;
    this.armed = null;
    for (const [action, button] of Object.entries(this.buttons)) {
      button.addEventListener("click", () => this.press(action));
    }
  }

  show(run) {
    this.runId = run.id;
    const over = run.status === "finished" || run.status === "failed";
    this.buttons.pause.disabled = over || run.control !== "run";
    this.buttons.resume.disabled = over || run.control !== "pause";
    this.buttons.stop.disabled = over || run.control === "stop";
  }

  disarm() {
    clearTimeout(this.armed);
    this.armed = null;
    this.buttons.stop.classList.remove("confirm");
    this.buttons.stop.textContent = "Stop";
  }

  async press(action) {
    if (action === "stop" && !this.armed) {
      this.buttons.stop.classList.add("confirm");
      this.buttons.stop.textContent = "Really stop?";
      this.armed = setTimeout(() => this.disarm(), 8000);
      return;
    }
    this.disarm();
    this.message.textContent = "";
    try {
      this.onChange(await api(`runs/${this.runId}/${action}`, { method: "POST" }));
    } catch (error) {
      this.message.textContent = `${action} refused (${error.status ?? "network"}): ${error.message}`;
    }
  }
}
