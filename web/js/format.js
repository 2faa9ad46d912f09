// Small display helpers.

export const STATUS_TEXT = {
  training: "training",
  waiting_for_labels: "waiting for labels",
  paused: "paused",
  finished: "finished",
  stopped: "stopped",
  failed: "failed",
};

// A run's state in a word: one the operator stopped ends "finished" with control "stop", and says
// stopped (as the labeling UI does), not finished.
export function shownStatus(run) {
  return run.status === "finished" && run.control === "stop" ? "stopped" : run.status;
}

// A run whose trainer should be calling the service (the runs list and the run's header watch it).
export const expectsTrainer = (run) => ["training", "waiting_for_labels", "paused"].includes(run.status);

// Stopped or over: the service takes no more labels for it (nor discards, nor instructions).
export const isClosed = (run) => run.control === "stop" || ["finished", "failed"].includes(run.status);

// An operator's pause or stop the trainer has not acted on yet (a paused run already says paused).
export function controlPending(run) {
  return run.control !== "run" && !["finished", "failed", "stopped"].includes(run.status)
    && !(run.control === "pause" && run.status === "paused");
}

export function ago(isoTime, now = Date.now()) {
  if (!isoTime) return "—";
  const s = Math.max(0, (now - Date.parse(isoTime)) / 1000);
  if (s < 60) return `${Math.floor(s)} s ago`;
  if (s < 3600) return `${Math.floor(s / 60)} min ago`;
  if (s < 86400) return `${(s / 3600).toFixed(1)} h ago`;
  return `${(s / 86400).toFixed(1)} d ago`;
}

// "1 label", "2 labels": `n` as shown (a number or its text), the word singular for exactly one.
export const plural = (n, word, words = `${word}s`) => `${n} ${String(n) === "1" ? word : words}`;

export const ordinal = (n) => `${n}${[11, 12, 13].includes(n % 100) ? "th" : { 1: "st", 2: "nd", 3: "rd" }[n % 10] ?? "th"}`;

export const of = (n, total) => (total == null ? `${n}` : `${n} / ${total}`);

export function num(x, digits = 2) {
  if (x == null || Number.isNaN(x)) return "—";
  return Math.abs(x) >= 1000 ? Math.round(x).toLocaleString("en") : Number(x.toFixed(digits)).toString();
}

export const percent = (x) => (x == null ? "—" : `${Math.round(100 * x)}%`);

// Run `fn` at most once per `ms`; calls in between are merged into one trailing call.
export function coalesce(fn, ms) {
  let timer = null;
  let last = 0;
  return () => {
    if (timer) return;
    const wait = Math.max(0, last + ms - performance.now());
    timer = setTimeout(() => {
      timer = null;
      last = performance.now();
      fn();
    }, wait);
  };
}

// Requests whose answers can come back out of order: each takes a number (`ask`), and its answer
// is `fresh` only if no later request's answer was taken; `skip` makes every answer asked for so
// far stale (something newer was shown another way).
export class Latest {
  asked = 0;
  taken = 0;
  ask() {
    return ++this.asked;
  }
  fresh(n) {
    if (n <= this.taken) return false;
    this.taken = n;
    return true;
  }
  skip() {
    this.taken = this.asked;
  }
}

export function escapeHtml(text) {
  return String(text).replace(/[&<>"']/g, (c) => `&#${c.charCodeAt(0)};`);
}
