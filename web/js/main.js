// The operators' dashboard: the runs list, and the selected run (#run=ID) below it.
// Open as {service}/?token=OPERATOR_TOKEN (optionally &ui=LABELING_UI_URL for the 3-D watch link).

import { api, setToken, takeTokenFromUrl, token } from "./api.js";
import { LabelerPanel } from "./labelers.js";
import { renderRuns, tickTimes } from "./runs.js";
import { RunPage } from "./run.js";

const $ = (selector) => document.querySelector(selector);
const runsBody = $("#runs-body");
const runPage = new RunPage($("#run"), showConnection);
const RUNS_WAIT_S = 20;
let runs = [];
let started = 0; // bumped by a new token: the old poll loop ends
let missing = null; // a run the service does not know: not asked for again until the runs list has it
let opening = 0; // bumped by each open: a failure of one the operator has left is not shown

let reported = "no token"; // what the run's stream (or the runs poll) last said of the connection
let silent = false; // the service keeps its connections open but answers nothing (stalled)

let changes = 0; // connection changes seen: a long poll sent before one may have been re-sent by the browser

function showConnection(state) {
  if (state !== reported) changes += 1;
  reported = state;
  const shown = silent && (state === "live" || state === "down") ? "silent" : state;
  const pill = $("#connection");
  pill.className = `pill ${shown === "live" ? "live" : "down"}`;
  pill.textContent = {
    live: "live", down: "reconnecting…", closed: "disconnected", refused: "token refused", silent: "not responding",
  }[shown] ?? shown;
}

// A service that stops answering (frozen, its machine swapping hard) keeps its connections open, so
// the stream hears no error and the badge said "live" throughout. The runs list's long poll answers
// within its wait: one that has not within STALL_S more says "not responding" until it does. (A
// separate health check would wait for a free connection, six per host in HTTP/1.1, which three
// dashboard tabs hold with their streams and polls: "not responding" of a service that is fine.)
// A poll whose connection broke meanwhile (a service restarted by `collie up`, which keeps its port
// open) may have been re-sent by the browser itself into the waiting port: its wait starts when the
// new service reads it, so it is given another window (was: "not responding" of a service up again).
const STALL_S = 10;
function stalled(waitS) {
  let seen = changes;
  let timer;
  const overdue = () => {
    if (changes !== seen) {
      seen = changes;
      timer = setTimeout(overdue, (waitS + STALL_S) * 1000);
      return;
    }
    silent = true;
    showConnection(reported);
  };
  timer = setTimeout(overdue, (waitS + STALL_S) * 1000);
  return () => {
    clearTimeout(timer);
    if (silent) {
      silent = false;
      showConnection(reported);
    }
  };
}

function selectedRun() {
  const match = /run=(\d+)/.exec(window.location.hash);
  return match ? Number(match[1]) : null;
}

// No token, or one the service refused (`message`, its reason): the page says what it needs, once and
// the same in each table, shows no run, and its forms wait for a token the service takes.
function askForToken(message) {
  $("#token-form").hidden = false;
  $("#token-error").textContent = message ? `token refused: ${message}` : "";
  const why = message ? "this token was refused" : "no token";
  const needed = (columns) => `<tr><td colspan="${columns}" class="muted">${why}: paste an operator token above ` +
    "(the dashboard link <code>collie up</code> prints carries one)</td></tr>";
  runsBody.innerHTML = needed(8);
  labelers.lock(needed(5));
  runs = [];
  runPage.close();
  $("#run").hidden = true;
  $("#run-problem").hidden = true;
  showConnection(message ? "refused" : "no token");
}

// "#run=abc": a link that names no run number (was ignored, and the newest run shown as if asked for)
function unreadableRun() {
  const asked = /run=([^&]*)/.exec(window.location.hash);
  if (!asked || /^\d+$/.test(asked[1])) return null;
  try {
    return decodeURIComponent(asked[1]);
  } catch {
    return asked[1]; // "%" alone, or a cut escape: shown as written
  }
}

async function openSelected() {
  const unreadable = unreadableRun();
  if (unreadable != null) {
    renderRuns(runsBody, runs, null);
    runPage.close();
    $("#run").hidden = true;
    $("#run-problem").textContent = `"#run=${unreadable}" names no run (a run is a number, as #run=3) — pick one from the runs above.`;
    $("#run-problem").hidden = false;
    return;
  }
  const runId = selectedRun() ?? runs[0]?.id ?? null;
  renderRuns(runsBody, runs, runId);
  if (runId == null || runId === runPage.runId) return;
  if (runId === missing && !runs.some((r) => r.id === runId)) return;
  const problem = $("#run-problem");
  const open = ++opening;
  try {
    await runPage.open(runId, sessionStorage.getItem("collie-ui"));
    if (runPage.runId === runId) {
      runPage.heard(runs.find((r) => r.id === runId)); // the list's word on its trainer, not at its next poll
      problem.hidden = true;
      missing = null; // a later link to it asks again
    }
  } catch (error) {
    if (error.status === 401) return askForToken(error.message);
    if (open !== opening) return; // another run was opened meanwhile: its page stays
    // no run shown (not the one open before): said where it would be; the badge is the connection's
    $("#run").hidden = true;
    if (error.status === 404) missing = runId;
    problem.textContent = `Run #${runId}: ${error.status === 404 ? "no such run on this service"
      : `could not be opened (${error.message})`} — pick one from the runs above.`;
    problem.hidden = false;
    if (error.status == null) showConnection("down"); // no answer at all
  }
}

// The runs list, kept live by a long poll: the service answers as soon as any run changes.
async function followRuns(generation) {
  let version = 0;
  let wait = 0; // the first answer at once
  while (generation === started) {
    try {
      const answered = stalled(wait);
      const page = await api(`dashboard/runs?after=${version}&wait_s=${wait}`).finally(answered);
      wait = RUNS_WAIT_S;
      if (generation !== started) return;
      version = page.version;
      runs = page.runs;
      runPage.heard(runs.find((r) => r.id === runPage.runId));
      $("#token-form").hidden = true;
      if (!runPage.source) showConnection("live"); // no run's stream to speak for the connection
      await openSelected();
    } catch (error) {
      if (error.status === 401) {
        askForToken(error.message);
        return;
      }
      showConnection("down");
      await new Promise((resolve) => setTimeout(resolve, 2000));
    }
  }
}

// Who the token is: a labeler's or the trainer's sees the runs, and the page hides what the service
// would refuse it (run control, quality, discards, labeler management, the disagreements' votes).
async function showRole(generation) {
  try {
    const me = await api("me");
    if (generation !== started) return;
    document.body.dataset.role = me.role;
    const note = $("#role-note");
    note.hidden = me.role === "operator";
    note.textContent = me.role === "operator" ? "" : `Signed in as ${me.name}, a ${me.role}: this page shows the ` +
      "runs; pausing, stopping, the feedback policy, quality, discarding labels, managing labelers and " +
      "the disagreements take an operator's token.";
  } catch {
    // a refused token is said by the runs poll; the page keeps offering everything meanwhile
  }
}

function start() {
  started += 1;
  delete document.body.dataset.role;
  $("#role-note").hidden = true;
  showRole(started);
  followRuns(started);
  labelers.load();
  if (selectedRun() != null) openSelected(); // a linked run loads beside the list, not after it
}

takeTokenFromUrl();
const ui = new URL(window.location.href).searchParams.get("ui");
if (ui) sessionStorage.setItem("collie-ui", ui);
const labelers = new LabelerPanel($("#labelers"), sessionStorage.getItem("collie-ui"), askForToken);

runsBody.addEventListener("click", (event) => {
  const row = event.target.closest("tr[data-run-id]");
  if (row) window.location.hash = `run=${row.dataset.runId}`;
});
runsBody.addEventListener("keydown", (event) => { // a row is focusable (Tab): Enter or Space opens it
  const row = event.target.closest("tr[data-run-id]");
  if (row && (event.key === "Enter" || event.key === " ")) {
    event.preventDefault();
    window.location.hash = `run=${row.dataset.runId}`;
  }
});
window.addEventListener("hashchange", openSelected);
$("#token-form").addEventListener("submit", (event) => {
  event.preventDefault();
  setToken($("#token-input").value.trim());
  start();
});
setInterval(() => tickTimes(), 1000);

if (token()) start();
else askForToken("");
