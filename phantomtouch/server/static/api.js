// REST calls to the phantomtouch service (docs/protocol.md). Every refused request
// becomes an ApiError carrying the server's `error.message`.

export class ApiError extends Error {
  constructor(message, { status = 0, code = "" } = {}) {
    super(message);
    this.name = "ApiError";
    this.status = status;
    this.code = code;
  }
}

async function errorFrom(response) {
  let message = `${response.status} ${response.statusText}`.trim();
  let code = "";
  try {
    const body = await response.json();
    if (body && body.error) {
      message = body.error.message || message;
      code = body.error.code || "";
    } else if (body && typeof body.detail === "string") {
      message = body.detail;
    }
  } catch {
    // The body was not JSON: keep the status line.
  }
  return new ApiError(message, { status: response.status, code });
}

// A service started with a token serves this page at /?token=...; every call carries it.
export const token = new URLSearchParams(location.search).get("token");

// `text` sends a body that is already JSON text as it is (a file's own bytes, which the
// service parses itself: a byte order mark, any spelling).
async function request(method, path, { json, text, accept = "application/json", signal } = {}) {
  const headers = { Accept: accept };
  if (token) headers.Authorization = `Bearer ${token}`;
  const init = { method, headers, signal };
  if (json !== undefined || text !== undefined) {
    headers["Content-Type"] = "application/json";
    init.body = text !== undefined ? text : JSON.stringify(json);
  }
  let response;
  try {
    response = await fetch(path, init);
  } catch (exc) {
    if (exc.name === "AbortError") throw exc;
    throw new ApiError(`The service cannot be reached (${method} ${path}).`);
  }
  if (!response.ok) throw await errorFrom(response);
  return response;
}

async function json(method, path, options) {
  const response = await request(method, path, options);
  return response.status === 204 ? null : response.json();
}

export const api = {
  device: () => json("GET", "/device"),
  presets: () => json("GET", "/presets"),
  patterns: () => json("GET", "/patterns"),
  pattern: (name) => json("GET", `/patterns/${encodeURIComponent(name)}`),
  clips: () => json("GET", "/clips"),
  savePattern: (name, pattern) =>
    json("PUT", `/patterns/${encodeURIComponent(name)}`, { json: pattern }),
  deletePattern: (name) => json("DELETE", `/patterns/${encodeURIComponent(name)}`),
  playPattern: (name) => json("POST", `/patterns/${encodeURIComponent(name)}/play`, { json: {} }),
  touch: (touchRequest) => json("POST", "/touch", { json: touchRequest }),
  plan: (touchRequest, signal) => json("POST", "/render", { json: touchRequest, signal }),
  stop: () => json("POST", "/stop"),
  tactList: (limit) => json("GET", `/tact?limit=${limit}&offset=0`),
  putTact: (name, text) => json("PUT", `/tact/${encodeURIComponent(name)}`, { text }),
  playTact: (name) => json("POST", `/tact/${encodeURIComponent(name)}/play`, { json: {} }),
  workspaces: (limit) => json("GET", `/bhaptics/workspaces?limit=${limit}&offset=0`),
  putWorkspace: (id, text) =>
    json("PUT", `/bhaptics/workspaces/${encodeURIComponent(id)}`, { text }),
  deleteWorkspace: (id) => json("DELETE", `/bhaptics/workspaces/${encodeURIComponent(id)}`),
  health: () => json("GET", "/health"),
  putWearer: (name, profile) =>
    json("PUT", `/wearers/${encodeURIComponent(name)}`, { json: profile }),
  wearerRun: (name) => json("GET", `/wearers/${encodeURIComponent(name)}/run`),
  putWearerRun: (name, run) =>
    json("PUT", `/wearers/${encodeURIComponent(name)}/run`, { json: run }),
  deleteWearerRun: (name) => json("DELETE", `/wearers/${encodeURIComponent(name)}/run`),
  activeWearer: () => json("GET", "/wearer"),
  useWearer: (name, band) => json("PUT", "/wearer", { json: { name, band } }),
  noWearer: () => json("DELETE", "/wearer"),
  async wav(touchRequest) {
    const response = await request("POST", "/render", { json: touchRequest, accept: "audio/wav" });
    return response.blob();
  },
};
