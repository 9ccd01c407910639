// The pattern designer: a path (a preset, a saved pattern or one drawn on the armband)
// plus the settings the user changed turn into a touch request (docs/protocol.md). Its
// plan and gain curves are previewed as it changes; it can be played, saved and rendered
// to a WAV file.

import { api } from "./api.js";
import { formatNumber } from "./units.js";

const PREVIEW_DELAY_MS = 200;
const DRAWN = "drawn";
const DRAWN_DEFAULTS = {
  speed_cm_s: 5,
  carrier: { kind: "sine", freq_hz: 100 },
  intensity: "low",
  law: "power",
};
const PRESET_GROUPS = {
  "exp2/": "Experiment 2: the four strokes",
  "vr/": "VR touches",
  "exp1/": "Experiment 1: stimuli",
};

const $ = (id) => document.getElementById(id);

export class Designer {
  // ui: { armband, chart, session, showError(message), channelLabels() }
  constructor(ui) {
    this.ui = ui;
    this.presets = [];
    this.saved = [];
    this.stored = new Map();
    this.drawn = [];
    this.planned = null;
    this.plannedKey = "";
    this.previewTimer = 0;
    this.previewAbort = null;
    this.stops = 0;
    this.animation = 0;
    this.form = {
      source: $("source"), speed: $("speed"), carrier: $("carrier"), freq: $("carrier-freq"),
      clip: $("carrier-clip"),
      modulation: $("modulation"), modIndex: $("mod-index"), modFreq: $("mod-freq"),
      intensity: $("intensity"), relative: $("relative"), law: $("law"),
    };
    for (const input of Object.values(this.form)) {
      input.addEventListener("input", () => this.changed());
      input.addEventListener("change", () => this.changed());
    }
    $("play").addEventListener("click", () => this.play());
    $("download").addEventListener("click", () => this.download());
    $("save-form").addEventListener("submit", (event) => {
      event.preventDefault();
      this.save();
    });
    $("clear-path").addEventListener("click", () => this.setDrawn([]));
    $("refresh-library").addEventListener("click", () => this.loadLibrary());
    $("reset-settings").addEventListener("click", () => this.resetSettings());
  }

  // Every setting back to the pattern's own: the path as it is.
  resetSettings() {
    const f = this.form;
    f.speed.value = "";
    for (const select of [f.carrier, f.modulation, f.intensity, f.law]) select.value = "";
    this.changed();
  }

  async load() {
    const [presets] = await Promise.all([api.presets(), this.loadLibrary()]);
    this.presets = presets;
    this.fillSources();
    this.changed();
  }

  // --- sources -----------------------------------------------------------------------

  fillSources() {
    const select = this.form.source;
    const current = select.value;
    select.replaceChildren();
    const drawn = new Option(
      this.drawn.length ? "Drawn on the armband" : "Drawn on the armband (draw one first)",
      DRAWN,
    );
    drawn.disabled = this.drawn.length === 0;
    select.add(drawn);
    const group = (label, names, kind) => {
      if (!names.length) return;
      const node = document.createElement("optgroup");
      node.label = label;
      for (const name of names) node.appendChild(new Option(name, `${kind}:${name}`));
      select.appendChild(node);
    };
    const presets = (prefix) => this.presets.map((p) => p.name).filter((n) => n.startsWith(prefix));
    group(PRESET_GROUPS["exp2/"], presets("exp2/"), "preset");
    group(PRESET_GROUPS["vr/"], presets("vr/"), "preset");
    group("Saved patterns", this.saved.map((p) => p.name), "saved");
    group(PRESET_GROUPS["exp1/"], presets("exp1/"), "preset");
    const known = Object.keys(PRESET_GROUPS);
    group("Other presets", presets("").filter((n) => !known.some((k) => n.startsWith(k))), "preset");
    if ([...select.options].some((o) => o.value === current && !o.disabled)) {
      select.value = current;
    } else {
      const first = this.presets.find((p) => p.name.startsWith("exp2/")) || this.presets[0];
      select.value = first ? `preset:${first.name}` : "";
    }
  }

  source() {
    const value = this.form.source.value || "";
    if (value === DRAWN) return { kind: DRAWN, name: "drawn-path" };
    const [kind, ...rest] = value.split(":");
    return { kind, name: rest.join(":") };
  }

  setDrawn(points) {
    this.drawn = points;
    $("clear-path").disabled = points.length === 0;
    if (points.length) this.form.source.value = DRAWN;
    this.fillSources();
    this.changed();
  }

  addDrawnPoint(point) {
    const points = this.source().kind === DRAWN ? this.drawn.concat([point]) : [point];
    this.setDrawn(points);
  }

  // --- the touch request ---------------------------------------------------------------

  // The settings the user changed, as TouchPattern fields; `null` removes a field.
  overrides() {
    const f = this.form;
    const out = {};
    if (f.speed.value.trim() !== "") {
      out.speed_cm_s = Number(f.speed.value);
      out.duration_s = null;
    }
    if (f.carrier.value === "noise") out.carrier = { kind: "noise" };
    else if (f.carrier.value === "clip") out.carrier = { kind: "clip", clip: f.clip.value };
    else if (f.carrier.value) out.carrier = { kind: f.carrier.value, freq_hz: Number(f.freq.value) };
    if (f.modulation.value === "none") out.modulation = null;
    else if (f.modulation.value) {
      out.modulation = {
        index: Number(f.modIndex.value),
        freq_hz: f.modulation.value === "stroke" ? "stroke" : Number(f.modFreq.value),
      };
    }
    if (f.intensity.value) {
      out.intensity = f.intensity.value === "relative" ? Number(f.relative.value) : f.intensity.value;
      out.level_db = null;
    }
    if (f.law.value) out.law = f.law.value;
    return out;
  }

  // A whole TouchPattern for the current source, or null when only the server knows it
  // (a preset).
  pattern() {
    const source = this.source();
    if (source.kind === DRAWN) {
      return merge(
        { path: { kind: "polyline", points_cm: this.drawn }, ...DRAWN_DEFAULTS },
        this.overrides(),
      );
    }
    if (source.kind === "saved" && this.stored.has(source.name)) {
      return merge(this.stored.get(source.name), this.overrides());
    }
    return null;
  }

  touchRequest() {
    const source = this.source();
    const overrides = this.overrides();
    if (source.kind === "preset") {
      // The service ignores null overrides and lets speed_cm_s replace duration_s and
      // intensity replace level_db by itself; "no modulation" is a modulation index of 0.
      const changes = {};
      for (const [key, value] of Object.entries(overrides)) {
        if (key === "modulation" && value === null) changes.modulation = { index: 0 };
        else if (value !== null) changes[key] = value;
      }
      return Object.keys(changes).length
        ? { preset: source.name, overrides: changes } : { preset: source.name };
    }
    if (source.kind === "saved" && Object.keys(overrides).length === 0) {
      return { stored: source.name };
    }
    return this.pattern();
  }

  // --- form state and preview ------------------------------------------------------

  changed() {
    const f = this.form;
    const source = this.source();
    const inherit = source.kind === DRAWN ? "default" : source.kind === "saved"
      ? "as saved" : "preset's own";
    for (const select of [f.carrier, f.modulation, f.intensity, f.law]) {
      select.querySelector("[data-inherit]").textContent = inherit;
    }
    f.speed.placeholder = source.kind === DRAWN ? `${DRAWN_DEFAULTS.speed_cm_s} (default)` : inherit;
    f.freq.disabled = !(f.carrier.value === "sine" || f.carrier.value === "combined");
    f.clip.disabled = f.carrier.value !== "clip";
    f.modIndex.disabled = !(f.modulation.value === "stroke" || f.modulation.value === "freq");
    f.modFreq.disabled = f.modulation.value !== "freq";
    f.relative.disabled = f.intensity.value !== "relative";
    $("relative-out").textContent = formatNumber(f.relative.value);
    const entry = source.kind === "preset" ? this.presets.find((p) => p.name === source.name)
      : source.kind === "saved" ? this.saved.find((p) => p.name === source.name) : null;
    $("source-summary").textContent = source.kind === DRAWN
      ? `${this.drawn.length} point${this.drawn.length === 1 ? "" : "s"} drawn on the armband`
      : describe(entry && entry.summary);
    const savable = source.kind !== "preset";
    $("save").disabled = !savable;
    $("save-name").disabled = !savable;
    $("save-hint").hidden = savable;
    if (!$("save-name").value && source.kind === "saved") $("save-name").value = source.name;
    if (source.kind === "saved" && !this.stored.has(source.name)) {
      this.fetchStored(source.name);
    }
    clearTimeout(this.previewTimer);
    this.previewTimer = setTimeout(() => this.preview(), PREVIEW_DELAY_MS);
  }

  async fetchStored(name) {
    try {
      this.stored.set(name, await api.pattern(name));
      this.changed();
    } catch (exc) {
      this.ui.showError(exc.message);
    }
  }

  async preview() {
    const request = this.touchRequest();
    if (!request) return;
    const key = JSON.stringify(request);
    if (key === this.plannedKey && this.planned) return;
    if (this.previewAbort) this.previewAbort.abort();
    const abort = new AbortController();
    this.previewAbort = abort;
    try {
      const planned = await api.plan(request, abort.signal);
      if (abort.signal.aborted) return;
      this.planned = planned;
      this.plannedKey = key;
      $("plan-error").textContent = "";
      this.showPlan(planned);
    } catch (exc) {
      if (exc.name === "AbortError") return;
      this.planned = null;
      this.plannedKey = "";
      $("plan-error").textContent = `Cannot plan this pattern: ${exc.message}`;
      this.showPlan(null);
    }
  }

  showPlan(planned) {
    const values = {
      duration_s: planned && `${formatNumber(planned.duration_s, 3)} s`,
      path_length_cm: planned && `${formatNumber(planned.path_length_cm, 2)} cm`,
      speed_cm_s: planned && `${formatNumber(planned.speed_cm_s, 2)} cm/s`,
      strokes: planned && String(planned.strokes ?? 1),
      level_db: planned && (planned.level_db === null || planned.level_db === undefined
        ? "silent" : `${formatNumber(planned.level_db, 1)} dB`),
      frames: planned && Number(planned.frames).toLocaleString("en-US"),
    };
    for (const dd of document.querySelectorAll("#plan dd")) {
      const key = dd.dataset.key;
      dd.textContent = values[key] || "–";
      if (planned && planned[key] !== undefined && planned[key] !== null) {
        dd.dataset.value = String(planned[key]);
      } else {
        delete dd.dataset.value;
      }
    }
    const curves = planned && planned.curves;
    this.ui.chart.show(curves, this.ui.channelLabels(), planned && planned.duration_s);
    // A drawn path stays on the armband while its plan is refused: it is the user's work.
    const drawn = this.source().kind === DRAWN ? this.drawn : null;
    this.ui.armband.setPath(curves ? curves.positions_cm : drawn);
  }

  // --- actions -----------------------------------------------------------------------

  async play() {
    const request = this.touchRequest();
    if (!request) return;
    const key = JSON.stringify(request);
    const stops = this.stops;
    try {
      const job = await api.touch(request);
      if (stops !== this.stops) return;  // stopped while the request was on its way
      this.startPlayhead(job, key === this.plannedKey ? this.planned : null);
    } catch (exc) {
      this.ui.showError(exc.message);
    }
  }

  playJob(job, label) {
    this.startPlayhead({ ...job, label }, null);
  }

  startPlayhead(job, planned) {
    cancelAnimationFrame(this.animation);
    const label = job.label || this.source().name;
    $("job").textContent = `Playing ${label}: ${formatNumber(job.duration_s, 2)} s.`;
    const tick = () => {
      const now = this.ui.session.serverNowS();
      const start = Number(job.start_at_s);
      if (now === null || !Number.isFinite(start)) return;
      const t = now - start;
      if (t > job.duration_s) {
        this.endPlayhead();
        $("job").textContent = `Played ${label}.`;
        return;
      }
      if (planned && planned.curves && t >= 0) {
        this.ui.chart.setPlayhead(t);
        this.ui.armband.setPlayhead(positionAt(planned.curves, t));
      }
      this.animation = requestAnimationFrame(tick);
    };
    this.animation = requestAnimationFrame(tick);
  }

  endPlayhead() {
    cancelAnimationFrame(this.animation);
    this.animation = 0;
    this.ui.chart.setPlayhead(null);
    this.ui.armband.setPlayhead(null);
  }

  stopped() {
    this.stops += 1;
    this.endPlayhead();
    $("job").textContent = "Stopped.";
  }

  async save() {
    const input = $("save-name");
    if (!input.reportValidity()) return;
    const name = input.value.trim();
    const pattern = this.pattern();
    if (!pattern) return;
    $("job").textContent = `Saving ${name}…`;
    try {
      await api.savePattern(name, pattern);
    } catch (exc) {
      $("job").textContent = `Not saved: ${name} was refused.`;
      this.ui.showError(exc.message);
      return;
    }
    this.stored.set(name, pattern);
    $("job").textContent = `Saved ${name} to the library.`;
    await this.loadLibrary();
  }

  async download() {
    const request = this.touchRequest();
    if (!request) return;
    const button = $("download");
    button.disabled = true;
    button.setAttribute("aria-busy", "true");
    try {
      const blob = await api.wav(request);
      const url = URL.createObjectURL(blob);
      const link = document.createElement("a");
      link.href = url;
      link.download = `${this.source().name.replace(/[^A-Za-z0-9._-]+/g, "-")}.wav`;
      document.body.appendChild(link);
      link.click();
      link.remove();
      setTimeout(() => URL.revokeObjectURL(url), 10000);
    } catch (exc) {
      this.ui.showError(exc.message);
    } finally {
      button.disabled = false;
      button.removeAttribute("aria-busy");
    }
  }

  // --- the library -------------------------------------------------------------------

  async loadLibrary() {
    let clips;
    try {
      [this.saved, clips] = await Promise.all([api.patterns(), api.clips()]);
    } catch (exc) {
      this.ui.showError(exc.message);
      return;
    }
    this.fillClips(clips);
    this.stored.clear();
    const list = $("library");
    list.replaceChildren();
    for (const entry of this.saved) list.appendChild(this.libraryItem(entry));
    $("library-empty").hidden = this.saved.length > 0;
    if (this.presets.length) this.fillSources();
  }

  // The clips a designed stroke can take as its carrier (the choice is kept if it is still
  // there).
  fillClips(clips) {
    const select = this.form.clip;
    const chosen = select.value;
    select.replaceChildren();
    for (const clip of clips) {
      const option = document.createElement("option");
      option.value = clip.name;
      option.textContent = `${clip.name} (${formatNumber(clip.duration_s)} s)`;
      select.appendChild(option);
    }
    if (clips.some((clip) => clip.name === chosen)) select.value = chosen;
    const clipOption = this.form.carrier.querySelector("option[value=clip]");
    clipOption.disabled = clips.length === 0;
    clipOption.textContent = clips.length ? "Haptic clip" : "Haptic clip (none imported)";
  }

  libraryItem(entry) {
    const li = document.createElement("li");
    const text = document.createElement("div");
    text.className = "library-text";
    const name = document.createElement("strong");
    name.textContent = entry.name;
    const summary = document.createElement("span");
    summary.textContent = describe(entry.summary);
    text.append(name, summary);
    const buttons = document.createElement("div");
    buttons.className = "library-buttons";
    const button = (label, aria, action, cls = "secondary small") => {
      const b = document.createElement("button");
      b.type = "button";
      b.className = cls;
      b.textContent = label;
      b.setAttribute("aria-label", aria);
      b.addEventListener("click", action);
      buttons.appendChild(b);
    };
    button("Play", `Play ${entry.name}`, () => this.playSaved(entry.name));
    button("Edit", `Edit ${entry.name} in the designer`, () => {
      this.form.source.value = `saved:${entry.name}`;
      $("save-name").value = entry.name;
      this.resetSettings();
      this.form.source.focus();
    });
    button("Delete", `Delete ${entry.name}`, () => this.deleteSaved(entry.name), "danger small");
    li.append(text, buttons);
    return li;
  }

  async playSaved(name) {
    const stops = this.stops;
    try {
      const job = await api.playPattern(name);
      if (stops === this.stops) this.playJob(job, name);
    } catch (exc) {
      this.ui.showError(exc.message);
    }
  }

  async deleteSaved(name) {
    if (!window.confirm(`Delete the pattern ${name} from the library?`)) return;
    try {
      await api.deletePattern(name);
      await this.loadLibrary();
      this.changed();
    } catch (exc) {
      this.ui.showError(exc.message);
    }
  }
}

// Fields of `overrides` replace those of `base`; a null override removes the field.
function merge(base, overrides) {
  const out = { ...base };
  for (const [key, value] of Object.entries(overrides)) {
    if (value === null) delete out[key];
    else out[key] = value;
  }
  return out;
}

// A plan summary ({duration_s, path_length_cm, speed_cm_s, level_db, strokes, ...}) in
// one line.
function describe(summary) {
  if (!summary) return "";
  if (typeof summary === "string") return summary;
  const parts = [`${formatNumber(summary.duration_s, 2)} s`];
  if (summary.path_length_cm > 0) {
    parts.push(`${formatNumber(summary.path_length_cm, 1)} cm at `
      + `${formatNumber(summary.speed_cm_s, 1)} cm/s`);
  }
  if (summary.strokes > 1) parts.push(`${summary.strokes} strokes`);
  if (typeof summary.level_db === "number") parts.push(`${formatNumber(summary.level_db, 0)} dB`);
  return parts.join(" · ");
}

// The planned phantom position at time t, interpolated between curve samples.
function positionAt(curves, t) {
  const times = curves.times_s;
  const points = curves.positions_cm;
  if (!times || !points || !times.length) return null;
  if (t <= times[0]) return points[0];
  let lo = 0;
  let hi = times.length - 1;
  if (t >= times[hi]) return points[hi];
  while (hi - lo > 1) {
    const mid = (lo + hi) >> 1;
    if (times[mid] <= t) lo = mid;
    else hi = mid;
  }
  const f = (t - times[lo]) / (times[hi] - times[lo] || 1);
  return [
    points[lo][0] + f * (points[hi][0] - points[lo][0]),
    points[lo][1] + f * (points[hi][1] - points[lo][1]),
  ];
}
