// Run control: pause, resume, stop, and the feedback timeout policy (operator token). Stop asks for
// a second click. The service is the judge of who may do what: a refusal (wrong token, finished
// run, a bad number) is shown, never hidden.

import { api } from "./api.js";

export function policyText(timeoutS) {
  return timeoutS == null ? "wait for every label" : `continue after ${Number(timeoutS.toPrecision(6))} s`;
}

export class Controls {
  constructor(root, onChange) {
    this.buttons = { pause: root.querySelector("#pause"), resume: root.querySelector("#resume"), stop: root.querySelector("#stop") };
    this.message = root.querySelector("#control-message");
    this.policy = {
      form: root.querySelector("#policy"),
      text: root.querySelector("#policy-text"),
      seconds: root.querySelector("#policy-seconds"),
      apply: root.querySelector("#policy-apply"),
      wait: root.querySelector("#policy-wait"),
    };
    this.onChange = onChange;
    this.runId = null;
    this.armed = null;
    for (const [action, button] of Object.entries(this.buttons)) {
      button.addEventListener("click", () => this.press(action));
    }
    this.policy.form.addEventListener("submit", (event) => {
      event.preventDefault();
      const text = this.policy.seconds.value.trim();
      if (text === "" || !Number.isFinite(Number(text)) || Number(text) <= 0) {
        this.message.textContent = "enter the seconds (more than 0) to wait for a session's labels";
        return;
      }
      this.setPolicy(Number(text));
    });
    this.policy.wait.addEventListener("click", () => this.setPolicy(null));
  }

  show(run) {
    this.runId = run.id;
    const over = run.status === "finished" || run.status === "failed";
    this.buttons.pause.disabled = over || run.control !== "run";
    this.buttons.resume.disabled = over || run.control !== "pause";
    this.buttons.stop.disabled = over || run.control === "stop";
    const timeout = run.feedback_timeout_s ?? null;
    this.policy.text.textContent = policyText(timeout);
    this.policy.form.dataset.timeout = timeout ?? "";
    const closed = over || run.control === "stop";
    this.policy.apply.disabled = closed;
    this.policy.seconds.disabled = closed;
    this.policy.wait.disabled = closed || timeout == null;
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

  // timeoutS: seconds, or null to wait for every label. The trainer re-times the session it is
  // waiting on from the session's start, so a shorter timeout may release it at once.
  async setPolicy(timeoutS) {
    this.message.textContent = "";
    try {
      this.onChange(await api(`runs/${this.runId}/feedback-policy`, { method: "POST", body: { timeout_s: timeoutS } }));
      this.policy.seconds.value = "";
    } catch (error) {
      this.message.textContent = `feedback policy refused (${error.status ?? "network"}): ${error.message}`;
    }
  }
}
