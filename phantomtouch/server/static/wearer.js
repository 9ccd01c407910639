// The wearer procedure (docs/wearer.md): intensity matching of each actuator against a
// reference actuator in two intervals ("which was stronger"), every answer saved on the
// service as it is given (PUT /wearers/{name}/run) so that a stopped run resumes; the
// profile stored at the end and applied to the running service on request (PUT /wearer);
// then a localisation check of phantom points, without and with the profile. Every
// stimulus is a POST /touch at a level (dB) bounded by the service's own ceiling.

import { api } from "./api.js";
import { Armband } from "./armband.js";
import { checkPoints, localisationCsv, localisationSummary } from "./localisation.js";
import { Levels, STAIRCASE, Staircase, seededRandom } from "./staircase.js";
import { formatNumber } from "./units.js";

const $ = (id) => document.getElementById(id);
const ANSWER_S = 1; // the wearer's time to answer a trial, s, until their own pace is measured
const FADE_S = 0.02;
export const CARRIERS = {
  sine_100hz: { kind: "sine", freq_hz: 100 },
  noise_40_500hz: { kind: "noise", low_hz: 40, high_hz: 500 },
};
const BAND_NAMES = { sine_100hz: "sine 100 Hz", noise_40_500hz: "noise 40–500 Hz" };

class Cancelled extends Error {}

function stillTouch(point, levelDb, carrier, durationS, startInMs = 0) {
  const fadeS = Math.min(FADE_S, durationS / 4);
  return {
    path: { kind: "polyline", points_cm: [point] },
    duration_s: durationS,
    fade_in_s: fadeS,
    fade_out_s: fadeS,
    level_db: levelDb,
    carrier,
    start_in_ms: startInMs,
  };
}

// A touch the engine refuses for a moment (503 busy: its render budget is taken) is asked
// again a few times before the run stops: a wearer's run should not end on a passing load.
const BUSY_RETRIES = 3;

async function touchWhenFree(body) {
  for (let attempt = 0; ; attempt += 1) {
    try {
      return await api.touch(body);
    } catch (exc) {
      if (exc.status !== 503 || attempt >= BUSY_RETRIES) throw exc;
      await new Promise((resolve) => setTimeout(resolve, 250 * (attempt + 1)));
    }
  }
}

export class WearerPanel {
  constructor({ device, showError }) {
    this.device = device;
    this.levels = new Levels(device.max_level_db);
    this.showError = showError;
    this.runs = []; // localisation runs of this page
    this.questions = 0; // questions asked so far: data-question on #wearer-trial
    this.pending = null; // {resolve, reject} of the question on screen
    this.trial = null; // the matching trial on screen, for "replay"
    this.savedRun = null; // the stored run of the wearer named, if it is unfinished
    this.stopping = false; // Cancel was pressed: the procedure ends at its next step
    this.picture = new Armband($("wearer-picture"), {
      down: (id, pos) => this.located(pos),
      move: () => {},
      up: () => {},
      drawn: () => {},
      addPoint: () => {},
    }, $("wearer-readout"));
    this.picture.build(device);
    for (const [index, actuator] of device.actuators.entries()) {
      $("wearer-reference").append(new Option(`${index + 1} (channel ${actuator.channel})`, String(index)));
    }
    $("wearer-name").addEventListener("input", () => this.named());
    $("wearer-name").addEventListener("change", () => this.lookUpRun());
    $("wearer-match").addEventListener("click", () => this.run(() => this.match()));
    $("wearer-restart").addEventListener("click", () => this.restart());
    $("wearer-cancel").addEventListener("click", () => this.cancel());
    $("wearer-check").addEventListener("click", () => this.run(() => this.check()));
    $("wearer-apply").addEventListener("click", () => this.apply());
    $("wearer-off").addEventListener("click", () => this.takeOff());
    $("wearer-first").addEventListener("click", () => this.respond(1));
    $("wearer-second").addEventListener("click", () => this.respond(2));
    $("wearer-replay").addEventListener("click", () => this.replay());
    $("wearer-csv").addEventListener("click", () => this.downloadCsv());
    document.addEventListener("keydown", (event) => {
      if ($("wearer-trial").dataset.state === "asking" && !event.target.closest("input, select")) {
        this.key(event);
      }
    });
    this.showInForce();
  }

  get name() {
    return $("wearer-name").value.trim();
  }

  get band() {
    return $("wearer-band").value;
  }

  get durationS() {
    return Number($("wearer-duration").value);
  }

  say(text) {
    $("wearer-message").textContent = text;
  }

  // A name that the library takes, or an Error saying what to type.
  checkedName() {
    if (!this.name || !$("wearer-name").checkValidity()) {
      $("wearer-name").focus();
      throw new Error("Give the wearer a name: 1 to 64 letters, digits, '.', '_' or '-'.");
    }
    return this.name;
  }

  named() {
    this.say("");
    this.savedRun = null;
    this.showResume();
  }

  // An unfinished run stored for the wearer named: offered as "Resume".
  async lookUpRun() {
    const name = this.name;
    if (!name || !$("wearer-name").checkValidity()) return;
    let run = null;
    try {
      run = await api.wearerRun(name);
    } catch (exc) {
      if (exc.status !== 404) this.say(`Cannot read the saved answers: ${exc.message}`);
    }
    if (name !== this.name) return;
    this.savedRun = run && !this.plan(run).finished ? run : null;
    this.showResume();
  }

  showResume() {
    const run = this.savedRun;
    $("wearer-restart").hidden = !run;
    $("wearer-match").textContent = run
      ? `Resume matching (${run.trials.length} answers saved)` : "Match intensities";
    if (run) {
      $("wearer-band").value = run.band;
      const reference = this.device.actuators.findIndex((a) => a.channel === run.reference_channel);
      if (reference >= 0) $("wearer-reference").value = String(reference);
    }
  }

  async restart() {
    try {
      await api.deleteWearerRun(this.checkedName());
    } catch (exc) {
      if (exc.status !== 404) this.say(`Cannot forget the saved answers: ${exc.message}`);
    }
    this.savedRun = null;
    this.showResume();
  }

  async run(procedure) {
    this.say("");
    this.stopping = false;
    delete $("wearer-trial").dataset.done;
    this.busy(true);
    $("wearer-progress").scrollIntoView({ block: "start" });
    try {
      await procedure();
    } catch (exc) {
      this.say(exc instanceof Cancelled ? this.stoppedText() : exc.message);
    } finally {
      this.busy(false);
      this.showResume();
      this.trial = null;
      this.picture.highlight();
      $("wearer-trial").dataset.state = "idle";
      $("wearer-trial-text").textContent = "";
    }
  }

  busy(running) {
    for (const id of ["wearer-match", "wearer-check", "wearer-restart", "wearer-name",
      "wearer-reference", "wearer-band"]) {
      $(id).disabled = running;
    }
    $("wearer-cancel").disabled = !running;
  }

  cancel() {
    this.stopping = true;
    if (!this.pending) return;
    const { reject } = this.pending;
    this.pending = null;
    reject(new Cancelled());
  }

  stoppedText() {
    const run = this.savedRun;
    return run && this.trial
      ? `Stopped after ${run.trials.length} answers; they are saved: press Resume to go on.`
      : "Stopped.";
  }

  respond(answer) {
    if (!this.pending) return;
    const { resolve } = this.pending;
    this.pending = null;
    resolve(answer);
  }

  key(event) {
    const actions = { 1: () => this.respond(1), 2: () => this.respond(2), r: () => this.replay() };
    const action = actions[event.key.toLowerCase()];
    if (!action) return;
    event.preventDefault();
    action();
  }

  located(pos) {
    if ($("wearer-trial").dataset.state === "locating") this.respond([pos.x_cm, pos.y_cm]);
  }

  waitFor(state, text) {
    this.questions += 1;
    $("wearer-trial").dataset.question = String(this.questions);
    $("wearer-trial").dataset.state = state;
    $("wearer-trial-text").textContent = text;
    return new Promise((resolve, reject) => { this.pending = { resolve, reject }; });
  }

  // --- intensity matching --------------------------------------------------------------

  // The staircases of a run (one per actuator but the reference), replayed from its
  // answers, and the seeded interval order advanced past them.
  plan(run) {
    const reference = this.device.actuators.findIndex((a) => a.channel === run.reference_channel);
    const staircases = new Map();
    this.device.actuators.forEach((a, index) => {
      if (index !== reference) staircases.set(a.channel, new Staircase(this.levels));
    });
    const random = seededRandom(`${this.name}`);
    for (const trial of run.trials) {
      random();
      staircases.get(trial.channel).answer(trial.test_stronger);
    }
    const all = [...staircases.values()];
    return { reference, staircases, random, finished: all.every((s) => s.done) };
  }

  async match() {
    const name = this.checkedName();
    if (!this.savedRun) await this.lookUpRun();
    let run = this.savedRun;
    if (!run || run.band !== this.band) {
      const reference = this.device.actuators[Number($("wearer-reference").value)];
      run = { band: this.band, reference_channel: reference.channel, trials: [] };
    }
    const { reference, staircases, random } = this.plan(run);
    const pace = { startedMs: performance.now(), answered: 0 };
    this.showProgress(run, staircases, pace);
    for (const [channel, staircase] of staircases) {
      const index = this.device.actuators.findIndex((a) => a.channel === channel);
      while (!staircase.done) {
        if (this.stopping) throw new Cancelled();
        this.trial = {
          testFirst: random() < 0.5,
          test: [this.device.actuators[index], this.levels.absoluteDb(staircase.levelDb)],
          reference: [this.device.actuators[reference], this.levels.referenceDb],
        };
        this.picture.highlight({ lit: [index + 1], marked: [reference + 1] });
        await this.play(this.trial);
        const answer = await this.waitFor(
          "asking",
          `Actuator ${index + 1} (lit) against actuator ${reference + 1}: which of the two `
          + "touches was stronger?",
        );
        const testStronger = (answer === 1) === this.trial.testFirst;
        run.trials.push({ channel, level_db: staircase.levelDb, test_stronger: testStronger });
        staircase.answer(testStronger);
        await api.putWearerRun(name, run);
        this.savedRun = run;
        pace.answered += 1;
        this.showProgress(run, staircases, pace);
      }
    }
    await this.store(name, run, staircases, reference);
    this.savedRun = null;
    this.showResume();
  }

  async play({ testFirst, test, reference }) {
    const intervals = testFirst ? [test, reference] : [reference, test];
    const carrier = CARRIERS[this.band];
    const secondAtMs = 1000 * (this.durationS + STAIRCASE.gapS);
    const touch = ([actuator, levelDb], atMs) => stillTouch(
      [actuator.x_cm, actuator.y_cm], levelDb, carrier, this.durationS, atMs,
    );
    await touchWhenFree(touch(intervals[0], 0));
    await touchWhenFree(touch(intervals[1], secondAtMs));
  }

  async replay() {
    if (!this.trial || $("wearer-trial").dataset.state !== "asking") return;
    try {
      await this.play(this.trial);
    } catch (exc) {
      this.say(`Replay: ${exc.message}`);
    }
  }

  // "Trial 12 of about 170, ~4 min left": the total shrinks when an actuator ends early at
  // the ceiling; the time left is at the wearer's own pace once a few answers are in.
  showProgress(run, staircases, pace) {
    const answered = run.trials.length;
    const remaining = [...staircases.values()].reduce((sum, s) => sum + s.remaining, 0);
    const total = answered + remaining;
    const guessS = 2 * this.durationS + STAIRCASE.gapS + ANSWER_S;
    const perTrialS = pace.answered >= 3
      ? (performance.now() - pace.startedMs) / 1000 / pace.answered : guessS;
    const leftMin = (remaining * perTrialS) / 60;
    const left = leftMin < 1 ? "under a minute left" : `~${Math.round(leftMin)} min left`;
    $("wearer-progress-bar").max = Math.max(1, total);
    $("wearer-progress-bar").value = answered;
    $("wearer-progress-text").textContent = remaining > 0
      ? `Trial ${answered + 1} of about ${total}, ${left}`
      : `${answered} trials answered`;
  }

  async store(name, run, staircases, reference) {
    const offsets = { [String(run.reference_channel)]: 0 };
    const atCeiling = [];
    for (const [channel, staircase] of staircases) {
      offsets[String(channel)] = Number(staircase.estimateDb().toFixed(2));
      if (staircase.limit) atCeiling.push([channel, staircase.limit]);
    }
    const limits = atCeiling.map(([channel, limit]) => `channel ${channel} at the ${limit}`);
    const note = `matched against actuator ${reference + 1} in ${run.trials.length} trials`
      + (limits.length ? `; ${limits.join(", ")}` : "");
    await api.putWearer(name, { offsets_db: { [run.band]: offsets }, note });
    this.showOffsets(offsets, new Map(atCeiling), run.trials.length);
  }

  showOffsets(offsets, limits, trials) {
    const list = $("wearer-offsets");
    list.replaceChildren();
    for (const [channel, db] of Object.entries(offsets)) {
      const item = document.createElement("li");
      item.dataset.channel = channel;
      item.dataset.offsetDb = String(db);
      const limit = limits.get(Number(channel));
      item.textContent = `channel ${channel}: ${formatNumber(db, 2)} dB`
        + (limit === "ceiling" ? " (at the ceiling: weaker than the reference even there)"
          : limit === "floor" ? " (at the floor: stronger than the reference even there)" : "");
      list.append(item);
    }
    $("wearer-progress-text").textContent = `Done: ${trials} trials; the profile is stored. `
      + "Apply it to the service, then run the localisation check.";
    $("wearer-trial").dataset.done = "match";
  }

  // --- the profile in force -------------------------------------------------------------

  async showInForce() {
    try {
      const active = await api.activeWearer();
      $("wearer-in-force").textContent = active.name
        ? `In force: ${active.name} (${BAND_NAMES[active.band] || active.band})`
        : "In force: none (the calibration alone)";
      $("wearer-in-force").dataset.name = active.name || "";
    } catch (exc) {
      this.say(`Cannot read the wearer in force: ${exc.message}`);
    }
  }

  async apply() {
    try {
      await api.useWearer(this.checkedName(), this.band);
      this.say("");
    } catch (exc) {
      this.say(`Apply: ${exc.message}`);
    }
    await this.showInForce();
  }

  async takeOff() {
    try {
      await api.noWearer();
    } catch (exc) {
      this.say(`Take it off: ${exc.message}`);
    }
    await this.showInForce();
  }

  // --- localisation check ---------------------------------------------------------------

  // Phantom points at the triangles' centres, in random order; the wearer clicks where each
  // was felt on the armband picture.
  async check() {
    const active = await api.activeWearer();
    const points = checkPoints(this.device).sort(() => Math.random() - 0.5);
    const rows = [];
    for (const [number, point] of points.entries()) {
      await touchWhenFree(
        stillTouch(point, this.levels.referenceDb, CARRIERS[this.band], this.durationS),
      );
      $("wearer-progress-bar").max = points.length;
      $("wearer-progress-bar").value = number;
      $("wearer-progress-text").textContent = `Point ${number + 1} of ${points.length}`;
      const felt = await this.waitFor("locating", "Click where you felt the touch.");
      this.picture.releaseAll();
      rows.push({ intended: point, felt });
      if (this.stopping) throw new Cancelled();
    }
    $("wearer-progress-bar").value = points.length;
    $("wearer-progress-text").textContent = `Localisation check done: ${points.length} points.`;
    this.runs.push({ wearer: active.name || "none", rows });
    this.showRuns();
  }

  showRuns() {
    const body = $("wearer-runs");
    body.replaceChildren();
    this.runs.forEach((run, index) => {
      const summary = localisationSummary(run.rows);
      const row = document.createElement("tr");
      row.dataset.errorCm = String(summary.errorCm);
      const cells = [index + 1, run.wearer, summary.errorCm, summary.biasXCm, summary.biasYCm];
      for (const value of cells) {
        const cell = document.createElement("td");
        cell.textContent = typeof value === "number" && !Number.isInteger(value)
          ? formatNumber(value, 2) : String(value);
        row.append(cell);
      }
      body.append(row);
    });
    this.showComparison();
    $("wearer-csv").disabled = this.runs.length === 0;
    $("wearer-trial").dataset.done = "check";
  }

  // Before and after: the latest run without a profile against the latest with one.
  showComparison() {
    const latest = (test) => [...this.runs].reverse().find(test);
    const without = latest((run) => run.wearer === "none");
    const fitted = latest((run) => run.wearer !== "none");
    const error = (run) => formatNumber(localisationSummary(run.rows).errorCm, 2);
    $("wearer-compare").textContent = without && fitted
      ? `Localisation error: ${error(without)} cm without a profile, ${error(fitted)} cm `
        + `with ${fitted.wearer}.`
      : "";
  }

  downloadCsv() {
    const blob = new Blob([localisationCsv(this.runs)], { type: "text/csv" });
    const link = document.createElement("a");
    link.href = URL.createObjectURL(blob);
    link.download = "localisation.csv";
    link.click();
    setTimeout(() => URL.revokeObjectURL(link.href), 1000);
  }
}
