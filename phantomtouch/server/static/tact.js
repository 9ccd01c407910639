// The .tact panel: a bHaptics Designer file dropped on the page (or chosen) is stored in
// the service's .tact library under its file's stem (PUT /tact/{name}); its summary is
// shown, or the service's refusal in one line; Play plays it (POST /tact/{name}/play) and
// the armband shows the live levels as it plays (the status stream, as for every touch).
// The service is the one parser: the file's text is sent as it is (docs/bhaptics.md).

import { api } from "./api.js";
import { LIST_LIMIT, libraryItem, showPage } from "./library_list.js";
import { formatNumber } from "./units.js";

const $ = (id) => document.getElementById(id);
const NAME_MAX_CHARS = 64;

// A library name from a file name (the name rule [A-Za-z0-9._-]{1,64}, no leading dot):
// the stem with every other character made "_", cut to 64 characters.
export function tactName(fileName) {
  const stem = fileName.replace(/\.tact$/i, "");
  const name = stem.replace(/[^A-Za-z0-9._-]/g, "_").replace(/^\.+/, "")
    .slice(0, NAME_MAX_CHARS);
  return name || "tact";
}

function hasFiles(event) {
  return Boolean(event.dataTransfer) && [...event.dataTransfer.types].includes("Files");
}

function describe(info) {
  return `${formatNumber(info.duration_s)} s · ${info.positions.join(", ")} · `
    + `${info.effects} effect${info.effects === 1 ? "" : "s"}`;
}

export class TactPanel {
  // showError(message): an alert for failures that are not the file's own (Play, listing).
  constructor({ showError }) {
    this.showError = showError;
    this.current = null;
    this.depth = 0;
    $("tact-file").addEventListener("change", () => {
      const file = $("tact-file").files[0];
      if (file) this.store(file);
      $("tact-file").value = "";
    });
    $("tact-play").addEventListener("click", () => this.current && this.play(this.current.name));
    $("tact-refresh").addEventListener("click", () => this.loadList());
    this.wireDrop();
  }

  // The whole page takes a dropped file (a file dropped elsewhere would replace the page).
  wireDrop() {
    const zone = $("tact-drop");
    document.addEventListener("dragenter", (event) => {
      if (!hasFiles(event)) return;
      this.depth += 1;
      zone.dataset.over = "true";
    });
    document.addEventListener("dragleave", (event) => {
      if (!hasFiles(event)) return;
      this.depth = Math.max(0, this.depth - 1);
      if (this.depth === 0) delete zone.dataset.over;
    });
    document.addEventListener("dragover", (event) => {
      if (!hasFiles(event)) return;
      event.preventDefault();
      event.dataTransfer.dropEffect = "copy";
    });
    document.addEventListener("drop", (event) => {
      if (!hasFiles(event)) return;
      event.preventDefault();
      this.depth = 0;
      delete zone.dataset.over;
      const file = event.dataTransfer.files[0];
      if (file) this.store(file);
    });
  }

  say(text, state) {
    const line = $("tact-message");
    line.textContent = text;
    line.dataset.state = state;
  }

  // Store the file under its stem; show its summary, or why the service refused it.
  async store(file) {
    const name = tactName(file.name);
    this.say(`Storing ${file.name}…`, "busy");
    let info;
    try {
      info = await api.putTact(name, await file.text());
    } catch (exc) {
      this.say(`${file.name} not stored: ${exc.message}`, "error");
      return;
    }
    this.show(info);
    this.say(`Stored ${file.name} as ${info.name}.`, "ok");
    await this.loadList();
  }

  show(info) {
    this.current = info;
    $("tact-name").textContent = info.name;
    for (const dd of $("tact-summary").querySelectorAll("dd[data-key]")) {
      const value = info[dd.dataset.key];
      dd.textContent = dd.dataset.key === "duration_s" ? `${formatNumber(value)} s`
        : Array.isArray(value) ? value.join(", ") : String(value);
    }
    $("tact-loaded").hidden = false;
  }

  async play(name) {
    try {
      const played = await api.playTact(name);
      this.say(`Playing ${name}: ${formatNumber(played.duration_s)} s, `
        + `${played.job_ids.length} voice${played.job_ids.length === 1 ? "" : "s"}.`, "ok");
    } catch (exc) {
      this.showError(`Cannot play ${name}: ${exc.message}`);
    }
  }

  // The first page of the library, each with its Play button.
  async loadList() {
    let entries;
    try {
      entries = await api.tactList(LIST_LIMIT);
    } catch (exc) {
      this.showError(`Cannot list the .tact library: ${exc.message}`);
      return;
    }
    const items = entries.map((entry) => libraryItem({ name: entry.name }, entry.name,
      describe(entry), {
        label: "Play",
        ariaLabel: `Play ${entry.name}`,
        onClick: () => this.play(entry.name),
      }));
    showPage("tact", items,
      `The first ${LIST_LIMIT} by name; GET /tact pages through the rest.`);
  }
}
