// Run control: pause, resume, stop, and the feedback timeout policy (operator token). Stop asks for
// a second click. The service is the judge of who may do what: a refusal (wrong token, finished
// run, a bad number) is shown, never hidden.

import { api } from "./api.js";
import { num, plural } from "./format.js";

// The longest feedback timeout the service takes (collie/schemas.py MAX_FEEDBACK_TIMEOUT_S), read from
// its OpenAPI schema once an operator starts on the field; null when unreadable (the service still
// checks, and its refusal is shown).
let maxTimeout = null;
export function feedbackTimeoutMax() {
  maxTimeout ??= fetch("openapi.json")
    .then((response) => response.json())
    .then((schema) => {
      const field = schema.components.schemas.FeedbackPolicy.properties.timeout_s;
      return (field.anyOf ?? [field]).map((type) => type.maximum).find(Number.isFinite) ?? null;
    })
    .catch(() => {
      maxTimeout = null; // asked again next time
      return null;
    });
  return maxTimeout;
}

// 604800 → "7 days", 7200 → "2 hours": the limit in words an operator can weigh.
const inWords = (s) => (s >= 86400 ? plural(num(s / 86400, 1), "day") : s >= 3600 ? plural(num(s / 3600, 1), "hour") : plural(num(s / 60, 1), "minute"));

// Seconds as digits with an optional point and exponent ("90", "1.5", "2e3"); "-3" is caught as ≤ 0.
const SECONDS = /^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$/;

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
    this.unsent = false; // the message says a request got no answer
    for (const [action, button] of Object.entries(this.buttons)) {
      button.addEventListener("click", () => this.press(action));
    }
    this.policy.seconds.addEventListener("focus", feedbackTimeoutMax); // known by the time Apply is pressed
    this.policy.form.addEventListener("submit", async (event) => {
      event.preventDefault();
      // A text field read strictly: a number field in Chromium read "1,5" as 15, and applied it.
      const text = this.policy.seconds.value.trim();
      if (!SECONDS.test(text)) {
        // "1,5" is 1.5 written with a comma; "1,500" may be 1500: no guess is offered for it
        const decimal = /^\d+,\d{1,2}$/.test(text) ? ` (for ${text.replace(",", ".")} s, write it with a point)` : "";
        this.message.textContent = text === ""
          ? "enter the seconds (more than 0) to wait for a session's labels"
          : `"${text}" is not a number of seconds${decimal}`;
        return;
      }
      if (Number(text) <= 0) {
        this.message.textContent = "enter the seconds (more than 0) to wait for a session's labels";
        return;
      }
      if (!Number.isFinite(Number(text))) { // 1e400: Infinity, which JSON would send as null (wait for all)
        this.message.textContent = `"${text}" is more seconds than a number holds: enter fewer`;
        return;
      }
      const max = await feedbackTimeoutMax();
      if (max != null && Number(text) > max) {
        this.message.textContent = `a session's labels can be waited for at most ${max} s (${inWords(max)}): enter fewer seconds, or Wait for every label`;
        return;
      }
      this.setPolicy(Number(text));
    });
    this.policy.wait.addEventListener("click", () => this.setPolicy(null));
  }

  show(run) {
    if (run.id !== this.runId || this.unsent) { // another run's "Really stop?" or words; an answer came since
      this.disarm();
      this.message.textContent = "";
      this.unsent = false;
    }
    this.runId = run.id;
    this.waiting = run.status === "waiting_for_labels";
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
      this.say(action, error);
    }
  }

  // A refusal as the service words it; no answer at all is no refusal (the request may not have
  // reached it), and goes once the service answers again (`show`).
  say(what, error) {
    this.unsent = error.status == null;
    this.message.textContent = this.unsent
      ? `${what} not done: no answer from the service (${error.message}); try again once it is back`
      : `${what} refused (${error.status}): ${error.message}`;
  }

  // timeoutS: seconds, or null to wait for every label. The trainer re-times the session it is
  // waiting on from the session's start, so a shorter timeout may release it at once.
  async setPolicy(timeoutS) {
    this.message.textContent = "";
    try {
      const waiting = this.waiting;
      this.onChange(await api(`runs/${this.runId}/feedback-policy`, { method: "POST", body: { timeout_s: timeoutS } }));
      this.policy.seconds.value = "";
      if (waiting && timeoutS != null) {
        this.message.textContent = `the trainer was waiting for labels: if its session has waited ${timeoutS} s already, it continues now with the labels that arrived`;
      }
    } catch (error) {
      this.say("feedback policy", error);
    }
  }
}
