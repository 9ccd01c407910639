// The games panel: bHaptics SDK2 workspaces, each a game's deployment (its events by
// name), stored in the service's library (GET /bhaptics/workspaces). A deployment file
// chosen here (the Developer Portal's JSON, a game's default config) is stored under the
// workspace id typed beside it, or, left empty, the file's own workspaceId
// (PUT /bhaptics/workspaces/{id}); its summary is listed, or the service's refusal, which
// names the field at fault, in one line. The service is the one parser: the file's text
// is sent as it is (docs/bhaptics.md, SDK2).

import { api } from "./api.js";
import { LIST_LIMIT, libraryItem, showPage } from "./library_list.js";

const $ = (id) => document.getElementById(id);

// The workspace id a deployment names (message.workspaceId, keys in any case), or "".
export function namedWorkspace(text) {
  let doc;
  try {
    doc = JSON.parse(text);
    if (typeof doc === "string") doc = JSON.parse(doc);
  } catch {
    return "";
  }
  const field = (obj, name) => {
    if (!obj || typeof obj !== "object" || Array.isArray(obj)) return undefined;
    const key = Object.keys(obj).find((k) => k.toLowerCase() === name.toLowerCase());
    return key === undefined ? undefined : obj[key];
  };
  const id = field(field(doc, "message"), "workspaceId") ?? field(doc, "workspaceId");
  return typeof id === "string" || typeof id === "number" ? String(id) : "";
}

function describe(info) {
  const game = info.game || "a game";
  return `${game} · ${info.events} event${info.events === 1 ? "" : "s"}, `
    + `${info.arm_events} on an arm · longest ${info.longest_ms} ms`;
}

export class WorkspacesPanel {
  // showError(message): an alert for failures that are not the file's own (listing).
  constructor({ showError }) {
    this.showError = showError;
    $("games-file").addEventListener("change", () => {
      const file = $("games-file").files[0];
      if (file) this.store(file);
      $("games-file").value = "";
    });
    $("games-refresh").addEventListener("click", () => this.loadList());
  }

  say(text, state) {
    const line = $("games-message");
    line.textContent = text;
    line.dataset.state = state;
  }

  // Store the file for the typed workspace id (else its own); list it, or say why not.
  async store(file) {
    const text = await file.text();
    const id = $("games-workspace").value.trim() || namedWorkspace(text);
    if (!id) {
      this.say(`${file.name} names no workspaceId: type the id the game connects with.`,
        "error");
      return;
    }
    this.say(`Storing ${file.name}…`, "busy");
    let info;
    try {
      info = await api.putWorkspace(id, text);
    } catch (exc) {
      this.say(`${file.name} not stored: ${exc.message}`, "error");
      return;
    }
    this.say(`Stored ${file.name} for workspace ${info.workspace_id}: ${describe(info)}.`, "ok");
    await this.loadList();
  }

  async remove(id) {
    try {
      await api.deleteWorkspace(id);
    } catch (exc) {
      this.showError(`Cannot remove workspace ${id}: ${exc.message}`);
      return;
    }
    this.say(`Removed workspace ${id}.`, "ok");
    await this.loadList();
  }

  // The first page of the workspaces, each with its Remove button.
  async loadList() {
    let entries;
    try {
      entries = await api.workspaces(LIST_LIMIT);
    } catch (exc) {
      this.showError(`Cannot list the bHaptics games: ${exc.message}`);
      return;
    }
    const items = entries.map((entry) => libraryItem({ workspace: entry.workspace_id },
      entry.workspace_id, describe(entry), {
        label: "Remove",
        ariaLabel: `Remove workspace ${entry.workspace_id}`,
        onClick: () => this.remove(entry.workspace_id),
      }));
    showPage("games", items,
      `The first ${LIST_LIMIT} by id; GET /bhaptics/workspaces pages through the rest.`);
  }
}
