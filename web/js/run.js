// One run's page: loaded in one request, then kept live from the run's own event stream (opened
// at the snapshot's last event id, so nothing is missed or applied twice).

import { api, stream, token } from "./api.js";
import { Controls } from "./controls.js";
import { Curves } from "./curves.js";
import { Latest, STATUS_TEXT, coalesce, controlPending, expectsTrainer, isClosed, plural, shownStatus } from "./format.js";
import { renderDisagreements, renderLabeling } from "./labeling.js";
import { SkillMap } from "./map.js";
import { InstructionsForm } from "./instructions.js";
import { QualityForm } from "./quality.js";

const MAX_POINTS = 500; // per curve: about one per pixel column of a panel
const LABELING_REFRESH_MS = 5000; // lease changes are not on the stream

export class RunPage {
  constructor(root, onConnection) {
    this.root = root;
    this.onConnection = onConnection;
    this.map = new SkillMap(root.querySelector("#map"), root.querySelector("#map-note"));
    this.curves = new Curves(root.querySelector("#curves"), root.querySelector("#curves-note"), MAX_POINTS, root.querySelector("#curves-help"));
    this.controls = new Controls(root, (run) => this.showAnswer(run));
    this.quality = new QualityForm(root, (run) => {
      this.showAnswer(run);
      this.labelingAnswers.skip(); // a labeling answer asked for before it would put the old settings back
      this.refreshLabeling();
    });
    this.instructions = new InstructionsForm(root, (run) => this.showAnswer(run));
    this.colourBy = root.querySelector("#colour-by");
    this.colourBy.addEventListener("change", () => this.map.set({ colourBy: this.colourBy.value }));
    this.refreshLabeling = coalesce(() => this.loadLabeling().catch(() => this.onConnection("down")), 300);
    this.renderCurves = coalesce(() => this.curves.render(), 200);
    this.source = null;
    this.timer = null;
    this.gen = 0; // bumped by each close (open closes first): an open still loading sees it is stale
    this.labelingAnswers = new Latest(); // each refresh and each rollouts event starts a request:
    this.rolloutAnswers = new Latest(); // their answers can come back out of order
    this.discard = { armed: null, message: "" };
    root.querySelector("#labeling-body").addEventListener("click", (event) => {
      const button = event.target.closest("button[data-discard]");
      if (button) this.discardLabels(Number(button.dataset.discard));
    });
  }

  async open(runId, watchUrl) {
    this.close();
    const gen = this.gen;
    this.labelingAnswers.skip(); // answers asked for before this open are older than its snapshot
    this.rolloutAnswers.skip();
    this.runId = runId;
    this.discard = { armed: null, message: "" };
    let page;
    try {
      page = await api(`dashboard/runs/${runId}?max_points=${MAX_POINTS}`);
    } catch (error) {
      if (gen === this.gen) this.runId = null; // the next runs update tries again
      throw error;
    }
    if (gen !== this.gen) return; // another open (this run's again too) or a close came meanwhile
    this.root.hidden = false;
    this.epoch = 0;
    this.lastEventId = page.last_event_id; // the newest run event shown: older answers do not undo it
    this.run = page.run;
    this.root.querySelector("#run-title").textContent = `Run #${runId} · ${page.run.env} ${page.run.task} · ${page.run.method}`;
    this.setWatchLink(watchUrl, runId);
    this.task = page.task;
    this.labelNames = page.labels.map((l) => l.name); // in value order: the API's words for 0, 1, 2
    this.showRun(page.run);
    const rule = this.root.querySelector("#run-rule"); // the instruction (no rule) or the rule's own words
    rule.textContent = page.run.instruction != null ? `Instruction (no task rule): ${page.run.instruction}`
      : page.run.task_definition ? page.run.task_definition.description : "";
    rule.hidden = !rule.textContent;
    this.renderLabeling(page);
    await Promise.all([
      this.map.set({ task: page.task, rollouts: page.rollouts, labelled: page.labelled, labels: page.labels, colourBy: this.colourBy.value, env: page.run.env }),
      this.curves.load(page.metrics),
    ]);
    if (gen !== this.gen) return; // the same while the charts drew: no stream or timer for this one
    this.seeEpoch(page.metrics.epochs.at(-1) ?? 0);
    this.seeEpoch(page.rollouts?.epoch ?? 0);
    const handlers = {
      status: (e) => this.onStatus(e),
      control: (e) => this.showRun({ ...this.run, control: e.data.control }),
      policy: (e) => this.showRun({ ...this.run, feedback_timeout_s: e.data.timeout_s }),
      metrics: (e) => this.onMetrics(e),
      rollouts: () => this.loadRollouts().catch(() => this.onConnection("down")),
      queries: () => this.refreshLabeling(),
      retired: () => this.refreshLabeling(),
      label: () => this.refreshLabeling(),
      withdrawn: () => this.refreshLabeling(),
    };
    for (const [name, handle] of Object.entries(handlers)) {
      handlers[name] = (e) => {
        if (source !== this.source) return; // a closed stream's last events are another page's
        this.lastEventId = Math.max(this.lastEventId, e.id);
        handle(e);
      };
    }
    const source = stream(`runs/${runId}/stream`, { after: page.last_event_id }, handlers, this.onConnection);
    this.source = source;
    this.timer = setInterval(() => this.refreshLabeling(), LABELING_REFRESH_MS);
  }

  // The runs list's word on this run's trainer (its last call to the service, refreshed by the
  // list's poll): a run whose trainer died says so here too, where its Pause and Stop are.
  heard(listed) {
    const mark = this.root.querySelector("#run-heard");
    if (listed && listed.id === this.runId && expectsTrainer(listed)) mark.dataset.time = listed.trainer_seen_at ?? listed.created_at;
    else {
      delete mark.dataset.time;
      mark.textContent = "";
      mark.classList.remove("silent");
    }
  }

  close() {
    this.gen += 1;
    document.title = "collie · operators";
    this.heard(null); // another run's word on its trainer
    this.source?.close();
    clearInterval(this.timer);
    this.source = null;
    this.runId = null;
  }

  setWatchLink(watchUrl, runId) {
    const link = this.root.querySelector("#watch-3d");
    this.watchUrl = watchUrl;
    link.hidden = !watchUrl;
    // the labeling UI's watch mode (labeling_ui/watch.py) signs in with this page's token
    if (watchUrl) link.href = this.uiLink({ watch: runId });
  }

  // A link into the labeling UI that signs in (only the tab it opens) with this page's token.
  uiLink(params) {
    const query = new URLSearchParams({ ...params, token: token() });
    return `${this.watchUrl}${this.watchUrl.includes("?") ? "&" : "?"}${query}`;
  }

  // The service's answer to this page's own request (pause, quality, ...): a snapshot taken when
  // the request was served. The stream may have shown newer events by the time it arrives (the
  // trainer's "paused" can overtake the answer to "pause"); those fields keep the values shown.
  showAnswer(run) {
    if (run.id !== this.runId) return; // another run was opened meanwhile
    if (run.last_event_id >= this.lastEventId) {
      this.lastEventId = run.last_event_id;
      return this.showRun(run);
    }
    const { status, epoch, control, feedback_timeout_s, n_labels, queue } = this.run; // counts: the labeling panel's
    this.showRun({ ...run, status, epoch, control, feedback_timeout_s, n_labels, queue });
  }

  showRun(run) {
    const closedBefore = this.closed();
    this.run = run;
    if (this.labelingView && this.closed() !== closedBefore) this.renderLabeling(this.labelingView); // no discard now
    const status = this.root.querySelector("#run-status");
    status.className = `status ${shownStatus(run)}`;
    status.textContent = (STATUS_TEXT[shownStatus(run)] ?? run.status) + (controlPending(run) ? ` (${run.control} requested)` : "");
    document.body.dataset.runStatus = run.status;
    document.body.dataset.runControl = run.control;
    // tabs of several runs told apart, and a run that waits for people seen from the tab bar
    document.title = `collie · run #${run.id} ${status.textContent}`;
    this.root.querySelector("#run-labels").textContent = run.n_labels;
    this.root.querySelector("#run-labels-total").textContent = run.n_total == null ? "" : ` / ${run.n_total}`;
    this.root.querySelector("#run-epochs-total").textContent = run.epochs_total == null ? "" : ` / ${run.epochs_total}`;
    this.seeEpoch(run.epoch);
    this.controls.show(run);
    this.quality.show(run);
    this.instructions.show(run);
  }

  // Stopped or over: the service keeps the run's labels as they are (no discard).
  closed() {
    return this.run != null && isClosed(this.run);
  }

  renderLabeling(view) {
    this.labelingView = view;
    renderLabeling(this.root.querySelector("#labeling-body"), view, this.run?.instruction != null, { ...this.discard, closed: this.closed() });
    if (this.run) {  // another operator may have changed them: the form's untouched inputs follow
      const { redundancy, gold_rate } = view.labeling;
      this.run = { ...this.run, redundancy, gold_rate }; // kept: the next showRun would put the old ones back
      this.quality.show(this.run);
    }
    // the labeling UI's review mode (labeling_ui/review.py) replays one query, labelling nothing
    const replay = this.watchUrl ? (queryId) => this.uiLink({ review: this.runId, query: queryId }) : null;
    renderDisagreements(this.root.querySelector("#disagreements-body"), this.root.querySelector("#disagreements-count"), view, this.task, this.labelNames ?? [], replay);
  }

  // The first click arms a labeler's button, the second discards their labels in this run.
  async discardLabels(labelerId) {
    if (this.discard.armed !== labelerId) {
      this.discard = { armed: labelerId, message: "" };
      this.renderLabeling(this.labelingView);
      return;
    }
    const runId = this.runId;
    const state = { armed: null, message: "" }; // this run's: another run opened meanwhile has its own
    this.discard = state;
    try {
      const done = await api(`runs/${runId}/labelers/${labelerId}/discard`, { method: "POST" });
      const counted = done.withdrawn.length === 1 ? "1 had counted and was" : `${done.withdrawn.length} had counted and were`;
      state.message = `discarded ${plural(done.queries.length, "label")} of ${done.labeler}; ${counted} withdrawn from the trainer`;
    } catch (error) {
      state.message = error.message; // the service names what is wrong (not an operator, a finished run)
    }
    if (runId !== this.runId) return;
    this.labelingAnswers.skip(); // an answer asked for before the discard would show the labels back
    this.refreshLabeling(); // a failed reload marks the connection down
  }

  seeEpoch(epoch) {
    if (epoch == null || epoch < this.epoch) return;
    this.epoch = epoch;
    this.root.querySelector("#run-epoch").textContent = epoch;
  }

  onStatus(event) {
    this.showRun({ ...this.run, status: event.data.status, epoch: event.data.epoch ?? this.run.epoch });
  }

  onMetrics(event) {
    this.curves.append(event.data.epoch, event.data.values, Date.parse(event.created_at) / 1000);
    this.seeEpoch(event.data.epoch);
    if (event.data.values.n_labels != null) {
      this.root.querySelector("#run-labels").textContent = Math.max(this.run.n_labels, event.data.values.n_labels);
    }
    this.renderCurves();
  }

  async loadRollouts() {
    const runId = this.runId;
    const asked = this.rolloutAnswers.ask();
    const [latest] = await api(`runs/${runId}/rollouts?limit=1&states=false`);
    if (latest && runId === this.runId && this.rolloutAnswers.fresh(asked)) {
      this.seeEpoch(latest.epoch);
      await this.map.set({ rollouts: latest });
    }
  }

  async loadLabeling() {
    const runId = this.runId;
    if (runId == null) return;
    const asked = this.labelingAnswers.ask();
    const view = await api(`dashboard/runs/${runId}/labeling`);
    if (runId !== this.runId || !this.labelingAnswers.fresh(asked)) return;
    this.renderLabeling(view);
    this.root.querySelector("#run-labels").textContent = view.labeling.n_labels;
    this.run = { ...this.run, n_labels: view.labeling.n_labels, queue: view.labeling.queue };
    await this.map.set({ labelled: view.labelled });
  }
}
