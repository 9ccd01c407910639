// The wearer procedure (docs/wearer.md): intensity matching of each actuator against a
// reference actuator in two intervals ("which was stronger"), trials placed by a 1-up-1-down
// staircase and the match fitted by maximum likelihood; then a localisation check of
// phantom points. Every stimulus is a POST /touch.

import { api } from "./api.js";
import { formatNumber } from "./units.js";

const $ = (id) => document.getElementById(id);
const SVG = "http://www.w3.org/2000/svg";

export const STAIRCASE = {
  baseIntensity: 0.2, // relative intensity of the reference interval
  startStepDb: 4, // first step; halved at each reversal down to minStepDb
  minStepDb: 0.5,
  trials: 24, // trials per actuator
  gapS: 0.25, // silence between the two intervals
};
const ANSWER_S = 1; // the wearer's time to answer a trial, s (for the time shown)
const MAX_DB = 20 * Math.log10(1 / STAIRCASE.baseIntensity); // test interval at intensity 1
const FIT = {
  lapse: 0.04, // answers at random on this fraction of trials (half of them "test")
  pointsDb: { from: -20, to: 20, step: 0.05 },
  spreadsDb: [0.5, 0.75, 1, 1.5, 2, 3], // logistic scale of the psychometric function
};
export const CARRIERS = {
  sine_100hz: { kind: "sine", freq_hz: 100 },
  noise_40_500hz: { kind: "noise", low_hz: 40, high_hz: 500 },
};

// A small seeded generator (mulberry32): the interval order, repeatable for one wearer.
export function seededRandom(text) {
  let state = [...text].reduce((h, c) => Math.imul(h ^ c.charCodeAt(0), 2654435761) >>> 0, 1);
  return () => {
    state = (state + 0x6d2b79f5) >>> 0;
    let t = state;
    t = Math.imul(t ^ (t >>> 15), t | 1);
    t ^= t + Math.imul(t ^ (t >>> 7), t | 61);
    return ((t ^ (t >>> 14)) >>> 0) / 4294967296;
  };
}

// One actuator's staircase: the level (dB re the reference) of its test interval. It places
// the trials (1-up-1-down: it converges on equal strength); the match is the maximum
// likelihood fit of a psychometric function to all its trials.
export class Staircase {
  constructor() {
    this.levelDb = 0;
    this.stepDb = STAIRCASE.startStepDb;
    this.lastDirection = 0;
    this.records = [];
  }

  get done() {
    return this.records.length >= STAIRCASE.trials;
  }

  // The test was judged stronger: step down; weaker: step up.
  answer(testStronger) {
    this.records.push([this.levelDb, testStronger]);
    const direction = testStronger ? -1 : 1;
    if (this.lastDirection !== 0 && direction !== this.lastDirection) {
      this.stepDb = Math.max(STAIRCASE.minStepDb, this.stepDb / 2);
    }
    this.lastDirection = direction;
    this.levelDb = Math.min(MAX_DB, Math.max(-MAX_DB, this.levelDb + direction * this.stepDb));
  }

  // The level felt as strong as the reference: P(test stronger) = lapse / 2 + (1 - lapse)
  // / (1 + exp(-(level - match) / spread)), match and spread by maximum likelihood on a grid.
  estimateDb() {
    let best = { logLikelihood: -Infinity, matchDb: 0 };
    const { from, to, step } = FIT.pointsDb;
    for (const spread of FIT.spreadsDb) {
      for (let i = 0; from + i * step <= to; i += 1) {
        const matchDb = from + i * step;
        let logLikelihood = 0;
        for (const [levelDb, testStronger] of this.records) {
          const p = FIT.lapse / 2 + (1 - FIT.lapse) / (1 + Math.exp(-(levelDb - matchDb) / spread));
          logLikelihood += Math.log(testStronger ? p : 1 - p);
        }
        if (logLikelihood > best.logLikelihood) best = { logLikelihood, matchDb };
      }
    }
    return best.matchDb;
  }
}

function stillTouch(actuator, intensity, carrier, durationS, startInMs) {
  return {
    path: { kind: "polyline", points_cm: [[actuator.x_cm, actuator.y_cm]] },
    duration_s: durationS,
    fade_in_s: Math.min(0.02, durationS / 4),
    fade_out_s: Math.min(0.02, durationS / 4),
    intensity,
    carrier,
    start_in_ms: startInMs,
  };
}

function phantomTouch(point, carrier, durationS) {
  return {
    path: { kind: "polyline", points_cm: [point] },
    duration_s: durationS,
    fade_in_s: Math.min(0.02, durationS / 4),
    fade_out_s: Math.min(0.02, durationS / 4),
    intensity: STAIRCASE.baseIntensity,
    carrier,
  };
}

// Phantom positions of the check: the centre of each triangle of the layout.
export function checkPoints(device) {
  return device.triangles.map((triangle) => {
    const corners = triangle.map((index) => device.actuators[index]);
    return [
      corners.reduce((sum, a) => sum + a.x_cm, 0) / 3,
      corners.reduce((sum, a) => sum + a.y_cm, 0) / 3,
    ];
  });
}

export function localisationSummary(rows) {
  const n = rows.length || 1;
  const mean = (f) => rows.reduce((sum, row) => sum + f(row), 0) / n;
  return {
    errorCm: mean((r) => Math.hypot(r.felt[0] - r.intended[0], r.felt[1] - r.intended[1])),
    biasXCm: mean((r) => r.felt[0] - r.intended[0]),
    biasYCm: mean((r) => r.felt[1] - r.intended[1]),
  };
}

export function localisationCsv(runs) {
  const lines = ["run,wearer,intended_x_cm,intended_y_cm,felt_x_cm,felt_y_cm,error_cm"];
  runs.forEach((run, index) => {
    for (const row of run.rows) {
      const error = Math.hypot(row.felt[0] - row.intended[0], row.felt[1] - row.intended[1]);
      const values = [index + 1, run.wearer, ...row.intended, ...row.felt, error];
      lines.push(values.map((v) => (typeof v === "number" ? v.toFixed(4) : v)).join(","));
    }
  });
  return `${lines.join("\n")}\n`;
}

export class WearerPanel {
  constructor({ device, showError }) {
    this.device = device;
    this.showError = showError;
    this.runs = [];
    this.questions = 0; // questions asked so far: data-question on #wearer-trial
    this.pending = null; // resolves with the wearer's answer of the current trial
    this.buildPicture();
    for (const [index, actuator] of device.actuators.entries()) {
      const option = new Option(`${index + 1} (channel ${actuator.channel})`, String(index));
      $("wearer-reference").append(option);
    }
    $("wearer-match").addEventListener("click", () => this.run(() => this.match()));
    $("wearer-check").addEventListener("click", () => this.run(() => this.check()));
    $("wearer-first").addEventListener("click", () => this.respond(1));
    $("wearer-second").addEventListener("click", () => this.respond(2));
    $("wearer-csv").addEventListener("click", () => this.downloadCsv());
  }

  get carrier() {
    return CARRIERS[$("wearer-band").value];
  }

  get durationS() {
    return Number($("wearer-duration").value);
  }

  async run(procedure) {
    $("wearer-match").disabled = $("wearer-check").disabled = true;
    try {
      await procedure();
    } catch (exc) {
      this.showError(`Wearer procedure: ${exc.message}`);
    } finally {
      $("wearer-match").disabled = $("wearer-check").disabled = false;
      $("wearer-trial").dataset.state = "idle";
    }
  }

  respond(answer) {
    if (!this.pending) return;
    const resolve = this.pending;
    this.pending = null;
    resolve(answer);
  }

  waitFor(state, text) {
    this.questions += 1;
    $("wearer-trial").dataset.question = String(this.questions);
    $("wearer-trial").dataset.state = state;
    $("wearer-trial-text").textContent = text;
    return new Promise((resolve) => { this.pending = resolve; });
  }

  // Each actuator against the reference, one staircase after another.
  async match() {
    const name = $("wearer-name").value.trim();
    if (!$("wearer-name").checkValidity() || !name) throw new Error("give the wearer a name");
    const reference = Number($("wearer-reference").value);
    const band = $("wearer-band").value;
    const offsets = {};
    const random = seededRandom(name);
    let trials = 0;
    for (const [index, actuator] of this.device.actuators.entries()) {
      if (index === reference) {
        offsets[String(actuator.channel)] = 0;
        continue;
      }
      const staircase = new Staircase();
      while (!staircase.done) {
        const testFirst = random() < 0.5;
        const testIntensity = STAIRCASE.baseIntensity * 10 ** (staircase.levelDb / 20);
        const intervals = [
          [this.device.actuators[reference], STAIRCASE.baseIntensity],
          [actuator, testIntensity],
        ];
        if (testFirst) intervals.reverse();
        const secondAtMs = 1000 * (this.durationS + STAIRCASE.gapS);
        await api.touch(stillTouch(...intervals[0], this.carrier, this.durationS, 0));
        await api.touch(stillTouch(...intervals[1], this.carrier, this.durationS, secondAtMs));
        const answer = await this.waitFor(
          "asking",
          `Actuator ${index + 1}: which of the two touches was stronger?`,
        );
        staircase.answer((answer === 1) === testFirst);
        trials += 1;
        $("wearer-progress").textContent = `${trials} trials`;
      }
      offsets[String(actuator.channel)] = Number(staircase.estimateDb().toFixed(2));
    }
    const profile = { offsets_db: { [band]: offsets }, note: `matched against actuator ${reference + 1}` };
    await api.putWearer(name, profile);
    this.showOffsets(offsets, trials);
  }

  showOffsets(offsets, trials) {
    const list = $("wearer-offsets");
    list.replaceChildren();
    for (const [channel, db] of Object.entries(offsets)) {
      const item = document.createElement("li");
      item.dataset.channel = channel;
      item.dataset.offsetDb = String(db);
      item.textContent = `channel ${channel}: ${formatNumber(db, 2)} dB`;
      list.append(item);
    }
    const trialS = 2 * this.durationS + STAIRCASE.gapS + ANSWER_S;
    $("wearer-progress").textContent = `${trials} trials, about ${formatNumber(trials * trialS / 60, 1)} min `
      + "of the wearer's time (two intervals, the gap and ${ANSWER_S} s to answer per trial)";
    $("wearer-trial").dataset.done = "match";
  }

  // Phantom points at the triangles' centres, in random order; the wearer clicks where each was felt.
  async check() {
    const health = await api.health();
    const points = checkPoints(this.device).sort(() => Math.random() - 0.5);
    const rows = [];
    for (const point of points) {
      await api.touch(phantomTouch(point, this.carrier, this.durationS));
      const felt = await this.waitFor("locating", "Click where you felt the touch.");
      rows.push({ intended: point, felt });
    }
    this.runs.push({ wearer: health.wearer || "none", rows });
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
    $("wearer-csv").disabled = this.runs.length === 0;
    $("wearer-trial").dataset.done = "check";
  }

  downloadCsv() {
    const blob = new Blob([localisationCsv(this.runs)], { type: "text/csv" });
    const link = document.createElement("a");
    link.href = URL.createObjectURL(blob);
    link.download = "localisation.csv";
    link.click();
    setTimeout(() => URL.revokeObjectURL(link.href), 1000);
  }

  // The armband as the wearer sees it, in cm (viewBox), 1 cm margin; a click names a point.
  buildPicture() {
    const svg = $("wearer-picture");
    const xs = this.device.actuators.map((a) => a.x_cm);
    const ys = this.device.actuators.map((a) => a.y_cm);
    const [x0, y0] = [Math.min(...xs) - 1, Math.min(...ys) - 1];
    const [w, h] = [Math.max(...xs) - x0 + 1, Math.max(...ys) - y0 + 1];
    svg.setAttribute("viewBox", `${x0} ${y0} ${w} ${h}`);
    svg.setAttribute("preserveAspectRatio", "none");
    const band = document.createElementNS(SVG, "rect");
    Object.entries({ x: x0, y: y0, width: w, height: h, rx: 0.8, class: "wearer-band" })
      .forEach(([k, v]) => band.setAttribute(k, v));
    svg.append(band);
    this.device.actuators.forEach((a, index) => {
      const dot = document.createElementNS(SVG, "circle");
      Object.entries({ cx: a.x_cm, cy: a.y_cm, r: 0.5, class: "wearer-actuator" })
        .forEach(([k, v]) => dot.setAttribute(k, v));
      dot.append(Object.assign(document.createElementNS(SVG, "title"), { textContent: `${index + 1}` }));
      svg.append(dot);
    });
    svg.addEventListener("click", (event) => {
      if ($("wearer-trial").dataset.state !== "locating") return;
      const box = svg.getBoundingClientRect();
      const x = x0 + ((event.clientX - box.left) / box.width) * w;
      const y = y0 + ((event.clientY - box.top) / box.height) * h;
      this.respond([x, y]);
    });
  }
}
