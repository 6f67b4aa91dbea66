// The participant page's only knowledge of server URLs: the REST API (docs/server.md), the 3D viewer
// and the one-tab lease (docs/frontend.md). Every call sends the token from the page's own address.

const API = "/api/v1";

/** The participant's token: the last segment of /p/{token}. */
export function tokenFromLocation(location = window.location) {
  const match = location.pathname.match(/^\/p\/([^/]+)\/?$/);
  if (!match) throw new Error(`this page expects an address /p/<token>, not ${location.pathname}`);
  return decodeURIComponent(match[1]);
}

/** A random id (crypto.randomUUID needs a secure context; getRandomValues does not). */
export function randomId(bytes = 16) {
  const values = crypto.getRandomValues(new Uint8Array(bytes));
  return Array.from(values, (b) => b.toString(16).padStart(2, "0")).join("");
}

/** An error answer from the server: status, message and (for 409) the participant's current state. */
export class ApiError extends Error {
  constructor(status, detail, state) {
    super(detail);
    this.status = status;
    this.state = state ?? null;
  }
}

const MAX_RETRY_WAIT_MS = 10000;

/** How long to wait before retrying a busy answer: its Retry-After (seconds), else a doubling back-off. */
function retryDelayMs(response, attempt) {
  const asked = Number(response.headers.get("Retry-After"));
  const fallback = 500 * 2 ** attempt;
  return Math.min(MAX_RETRY_WAIT_MS, Number.isFinite(asked) && asked > 0 ? asked * 1000 : fallback);
}

export class ParticipantApi {
  constructor(token) {
    this.token = token;
    this.held = new Map(); // path -> {tag, data}: the last answer of each poll, sent back as If-None-Match
  }

  get headers() {
    return { Authorization: `Bearer ${this.token}`, "Content-Type": "application/json" };
  }

  async request(method, path, body, { key = null, retries = 4, revalidate = false } = {}) {
    const headers = { ...this.headers };
    if (key) headers["Idempotency-Key"] = key;
    // A poll sends the tag of the answer it holds; "304 Not Modified" means that answer is still right.
    const held = revalidate ? this.held.get(path) : null;
    if (held) headers["If-None-Match"] = held.tag;
    for (let attempt = 0; ; attempt++) {
      let response;
      try {
        response = await fetch(API + path, {
          method, headers, body: body === undefined ? undefined : JSON.stringify(body), cache: "no-store",
        });
      } catch (networkError) {
        // The same Idempotency-Key makes a retry harmless if the first request did arrive.
        if (attempt >= retries) throw new ApiError(0, "the server cannot be reached", null);
        await new Promise((resolve) => setTimeout(resolve, 500 * 2 ** attempt));
        continue;
      }
      if (response.status === 204) return null;
      if (response.status === 304 && held) return held.data; // the same object: nothing changed
      if ((response.status === 503 || response.status === 429) && attempt < retries) {
        // Busy (a database lock, a limit): wait as long as the server asks, within reason, and try again.
        await new Promise((resolve) => setTimeout(resolve, retryDelayMs(response, attempt)));
        continue;
      }
      const data = await response.json().catch(() => ({}));
      if (!response.ok) throw new ApiError(response.status, data.detail || response.statusText, data.state);
      const tag = response.headers.get("ETag");
      if (revalidate && tag) this.held.set(path, { tag, data });
      return data;
    }
  }

  /** The entity tag of the last answer held for a polled path (null before the first). */
  heldTag(path) { return this.held.get(path)?.tag ?? null; }

  /** An action: a fresh Idempotency-Key per user action, reused by its retries. */
  act(path, body) {
    return this.request("POST", path, body, { key: randomId() });
  }

  state() { return this.request("GET", "/me", undefined, { retries: 0, revalidate: true }); }
  consent(agree, version) { return this.act("/me/consent", { agree, consent_version: version }); }
  instructionsRead() { return this.act("/me/instructions", undefined); }
  place(object, guard) { return this.act("/me/placements", { object, ...guard }); }
  finishDemonstration(guard) { return this.act("/me/demonstration/finish", guard); }
  startExecution(guard) { return this.act("/me/execution", guard); }
  /** The verdict, with how much of the robot's attempt the page played (0-1; null: the page could not tell). */
  assess(acceptable, guard, shownFraction = null) {
    return this.act("/me/assessment", { acceptable, ...guard, shown_fraction: shownFraction });
  }
  /** Show the finished execution again in the 3D view (its recorded motion); the server logs it. */
  replay(guard) { return this.act("/me/execution/replay", guard); }
  answerQuestionnaire(answers) { return this.act("/me/questionnaire", { answers }); }

  /** Attention telemetry or presence (kind: tab_hidden, window_blur, paste, still_here); never retried. */
  signal(kind, field = null) {
    return this.request("POST", "/me/signals", field ? { kind, field } : { kind }, { retries: 0 });
  }

  /** Prepare the 3D view for the current step: {available, url}. */
  openView() { return this.request("POST", "/me/view", undefined, { retries: 1 }); }
  /** The 2D view: the tables from above and the current step's recorded motion ({layout, motion, pending, ...}). */
  topView() { return this.request("GET", "/me/top-view", undefined, { retries: 1 }); }
  robot() { return this.request("GET", "/me/robot", undefined, { retries: 0, revalidate: true }); }

  claimTab(tabId, takeover = false) {
    return this.request("POST", "/me/tab", { tab_id: tabId, takeover }, { retries: 0 });
  }

  /** Free the lease while the page unloads (keepalive lets the request outlive the page). */
  releaseTab(tabId) {
    fetch(`${API}/me/tab/release`, {
      method: "POST", headers: this.headers, body: JSON.stringify({ tab_id: tabId }), keepalive: true,
    }).catch(() => {});
  }
}

/** Address of one of the participant page's own files (scripts, style sheet, pictures). */
export function assetUrl(name) {
  return `/participant/assets/${encodeURIComponent(name)}`;
}
