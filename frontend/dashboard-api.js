// The one module that knows the experimenter API's URLs. Every call sends the experimenter token.

const TOKEN_KEY = "tableteach.experimenterToken";
const API = "/api/v1";

/** The server refused a request: HTTP status and its message (what was wrong and what was expected). */
export class ApiError extends Error {
  constructor(status, detail, errors = null) {
    super(detail);
    this.status = status;
    this.detail = detail;
    this.errors = errors; // 422 on a study: [{field, message}] for every unacceptable field
  }
}

export function token() {
  return sessionStorage.getItem(TOKEN_KEY);
}

export function setToken(value) {
  sessionStorage.setItem(TOKEN_KEY, value);
}

export function clearToken() {
  sessionStorage.removeItem(TOKEN_KEY);
}

async function request(method, path, { body, csv, raw = false, bearer = token() } = {}) {
  const headers = { Accept: raw ? "text/csv" : "application/json" };
  if (bearer) headers.Authorization = `Bearer ${bearer}`;
  if (body !== undefined) headers["Content-Type"] = "application/json";
  if (csv !== undefined) headers["Content-Type"] = "text/csv";
  let response;
  try {
    const sent = csv !== undefined ? csv : body === undefined ? undefined : JSON.stringify(body);
    response = await fetch(path, { method, headers, body: sent });
  } catch (error) {
    throw new ApiError(0, `the server could not be reached (${error.message}); check that it is running`);
  }
  if (!response.ok) {
    let detail = `${response.status} ${response.statusText}`;
    let errors = null;
    try {
      const data = await response.json();
      if (data && data.detail) detail = typeof data.detail === "string" ? data.detail : JSON.stringify(data.detail);
      if (data && Array.isArray(data.errors)) errors = data.errors;
    } catch {
      // not JSON: keep the status line
    }
    throw new ApiError(response.status, detail, errors);
  }
  if (response.status === 204) return null;
  return raw ? response : response.json();
}

const enc = encodeURIComponent;

/** Check a token by listing the studies with it (nothing is stored unless it works). */
export async function checkToken(candidate) {
  return request("GET", `${API}/studies`, { bearer: candidate });
}

/** Log in with a name and password: {token, name, role, expires_at} (the token lasts 12 hours). */
export const login = (name, password) => request("POST", `${API}/login`, { body: { name, password }, bearer: null });
export const whoami = () => request("GET", `${API}/whoami`);
/** The logged-in person changes their own password; their other dashboard logins end. */
export const changePassword = (current, next) =>
  request("POST", `${API}/password`, { body: { current_password: current, new_password: next } });

// Accounts (owner only): people, their API tokens, passwords.
export const people = () => request("GET", `${API}/accounts`);
export const addPerson = (name, role, password) =>
  request("POST", `${API}/accounts`, { body: { name, role, password: password || null } });
export const disablePerson = (name) => request("POST", `${API}/accounts/${enc(name)}/disable`);
export const setPassword = (name, password) => request("POST", `${API}/accounts/${enc(name)}/password`, { body: { password } });
export const allTokens = () => request("GET", `${API}/accounts/all-tokens`);
export const issueToken = (name, label, days) => request("POST", `${API}/accounts/${enc(name)}/tokens`, { body: { label, days } });
export const revokeToken = (id) => request("DELETE", `${API}/accounts/tokens/${enc(id)}`);
export const audit = (limit = 500) => request("GET", `${API}/audit?limit=${enc(limit)}`);

/** The whole audit log as {filename, blob}. */
export async function auditCsv() {
  const response = await request("GET", `${API}/audit.csv`, { raw: true });
  return { filename: "audit.csv", blob: await response.blob() };
}

export const listStudies = (includeArchived = false) => request("GET", `${API}/studies?include_archived=${includeArchived}`);
export const getStudy = (id) => request("GET", `${API}/studies/${enc(id)}`);
export const createStudy = (spec) => request("POST", `${API}/studies`, { body: spec });
export const openStudy = (id) => request("POST", `${API}/studies/${enc(id)}/open`);
export const closeStudy = (id) => request("POST", `${API}/studies/${enc(id)}/close`);
export const updateStudy = (id, changes) => request("PATCH", `${API}/studies/${enc(id)}`, { body: changes });
export const archiveStudy = (id) => request("POST", `${API}/studies/${enc(id)}/archive`);
export const unarchiveStudy = (id) => request("POST", `${API}/studies/${enc(id)}/unarchive`);
export const deleteStudy = (id) => request("DELETE", `${API}/studies/${enc(id)}`);
export const statistics = (id, includePilot = false) =>
  request("GET", `${API}/studies/${enc(id)}/statistics?include_pilot=${includePilot}`);
export const cloneStudy = (id) => request("POST", `${API}/studies/${enc(id)}/clone`);
export const resetPilot = (id) => request("POST", `${API}/studies/${enc(id)}/pilot/reset`);
export const eraseParticipant = (id, pid) => request("DELETE", `${API}/studies/${enc(id)}/participants/${enc(pid)}`);
export const restoreParticipant = (id, pid) => request("POST", `${API}/studies/${enc(id)}/participants/${enc(pid)}/restore`);
export const helpParticipant = (id, pid) => request("POST", `${API}/studies/${enc(id)}/participants/${enc(pid)}/help`);
/** The standard questionnaires (SUS, NASA-TLX, Godspeed, trust) with their items, scoring and citations. */
export const instruments = () => request("GET", `${API}/instruments`);
export const describeFormula = (formula, objects = []) => request("GET", `${API}/formulas/describe?formula=${enc(formula)}`
  + (objects.length ? `&objects=${enc(objects.join(","))}` : ""));

export function live(id, dropoutMinutes) {
  const query = dropoutMinutes ? `?dropout_minutes=${enc(dropoutMinutes)}` : "";
  return request("GET", `${API}/studies/${enc(id)}/live${query}`);
}

export const history = (id, pid) => request("GET", `${API}/studies/${enc(id)}/participants/${enc(pid)}/history`);
export const curves = (id, finishedOnly = false, includePilot = false) =>
  request("GET", `${API}/studies/${enc(id)}/curves?finished_only=${finishedOnly}&include_pilot=${includePilot}`);

/** One participant's data replayed through other learners (specs such as flip=0.1), beside the study's own. */
export function whatIf(id, pid, learners) {
  const query = learners.map((l) => `learner=${enc(l)}`).join("&");
  return request("GET", `${API}/studies/${enc(id)}/participants/${enc(pid)}/what-if${query ? `?${query}` : ""}`);
}

export function replay(id, pid, { task_index, kind, index }) {
  return request("GET", `${API}/studies/${enc(id)}/participants/${enc(pid)}/replays/${enc(task_index)}/${enc(kind)}/${enc(index)}`);
}

// Reconciliation with Prolific: its submissions export, the per-id table, the bonus rule and file.
export const uploadSubmissions = (id, text) => request("PUT", `${API}/studies/${enc(id)}/prolific/submissions`, { csv: text });
export const reconciliation = (id) => request("GET", `${API}/studies/${enc(id)}/prolific/reconciliation`);
export const bonusRule = (id) => request("GET", `${API}/studies/${enc(id)}/prolific/bonus-rule`);
export const setBonusRule = (id, amounts) => request("PUT", `${API}/studies/${enc(id)}/prolific/bonus-rule`, { body: { amounts } });

/** The bulk-bonus file as {filename, text, blob}: lines "participant id,amount". */
export async function bonusFile(id) {
  const response = await request("GET", `${API}/studies/${enc(id)}/prolific/bonuses.csv`, { raw: true });
  const blob = await response.blob();
  return { filename: `${id}-bonuses.csv`, text: await blob.text(), blob };
}

export const EXPORTS = ["exports.zip", "participants.csv", "events.csv", "steps.csv", "beliefs.csv", "questionnaire.csv",
  "codebook.csv"];

/** One export file as {filename, blob} (fetched with the token: a plain link could not send it). */
export async function exportCsv(id, file, includePilot = false) {
  const response = await request("GET", `${API}/studies/${enc(id)}/exports/${enc(file)}?include_pilot=${includePilot}`,
    { raw: true });
  return { filename: `${id}-${file}`, blob: await response.blob() };
}

/** The choices the server accepts for a new study, read from its OpenAPI schema. */
export async function studyChoices() {
  const schema = await request("GET", "/openapi.json", { bearer: null });
  const props = schema.components.schemas.StudyIn.properties;
  const item = schema.components.schemas.ItemIn.properties;
  const task = schema.components.schemas.TaskIn.properties;
  const object = schema.components.schemas.ObjectIn;
  return {
    shapes: object.properties.shape.enum,
    // Each shape's size range in cm (the schema's rule per shape), e.g. {cup: [6, 10]}.
    sizes: Object.fromEntries(object.allOf.map((rule) => [rule.if.properties.shape.const,
      [rule.then.properties.size.anyOf[1].minimum, rule.then.properties.size.anyOf[1].maximum]])),
    priors: props.prior.enum, criteria: props.criterion.enum, conditions: props.conditions.items.enum,
    assignments: props.assignment.enum, itemKinds: item.kind.enum, taskKeys: task.key.enum,
    taskOrders: props.task_order.enum,
    defaults: Object.fromEntries(Object.entries(props).map(([k, v]) => [k, v.default])),
  };
}

/** The link to give participants (Prolific fills in the placeholders). */
export function joinLink(id, { prolific = false } = {}) {
  const base = `${location.origin}/study/${enc(id)}/join`;
  return prolific ? `${base}?PROLIFIC_PID={{%PROLIFIC_PID%}}&STUDY_ID={{%STUDY_ID%}}&SESSION_ID={{%SESSION_ID%}}` : base;
}
