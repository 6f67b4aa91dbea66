// The experimenter dashboard: log in, studies, a study's live participants and curves, one participant's history.
// Views are rebuilt from the API on every hash change (#/, #/new, #/audit, #/accounts, #/account, #/study/{id},
// #/study/{id}/edit, #/study/{id}/prolific, #/study/{id}/p/{pid}).
// All text from the server goes through textContent, never innerHTML.

import * as api from "./dashboard-api.js";
import { PALETTE, lineChart, quatYaw, tableView } from "./charts.js";
import { h, pretty } from "./dom.js";
import { OUTCOME_CODES, studyFormView } from "./dashboard-study-form.js";
import { errorBox, pill, saveBlob, setCrumbs, toast, when } from "./dashboard-ui.js";
import { prolificView } from "./dashboard-prolific.js";
import { accountsView, accountView } from "./dashboard-accounts.js";
import { consistencyNote, consistencyPill, whatIfSection } from "./dashboard-what-if.js";

const POLL_MS = 4000;
const app = document.getElementById("app");
const logoutButton = document.getElementById("logout");
const meLink = document.getElementById("me");
let cleanups = [];

// ---------------------------------------------------------------- small DOM helpers

function pct(p) {
  if (p === null || p === undefined) return "–";
  if (p < 0.001) return "<0.1%";
  if (p > 0.999) return ">99.9%";
  return `${(100 * p).toFixed(p < 0.01 || p > 0.99 ? 1 : 0)}%`;
}
const num = (v, digits = 2) => (v === null || v === undefined ? "–" : Number(v).toFixed(digits));
const KIND_NAMES = { practice: "Practice", demonstration: "Demonstration", query: "Query", test: "Test", done: "Done" };

function ago(iso) {
  if (!iso) return "–";
  const seconds = Math.max(0, (Date.now() - Date.parse(iso)) / 1000);
  if (seconds < 60) return `${Math.round(seconds)} s ago`;
  if (seconds < 3600) return `${Math.round(seconds / 60)} min ago`;
  if (seconds < 86400) return `${(seconds / 3600).toFixed(1)} h ago`;
  return `${Math.round(seconds / 86400)} d ago`;
}


// The page's attention telemetry (tab hidden, window left, pastes): flagged from this many signals in all.
const LOOKED_AWAY_FLAG = 3;
function signalsText(p) {
  const n = p.attention_signals ?? {};
  return `tab hidden ${n.tab_hidden ?? 0}×, window left ${n.window_blur ?? 0}×, pasted ${n.paste ?? 0}×`;
}
function lookedAway(p) {
  const n = p.attention_signals ?? {};
  return (n.tab_hidden ?? 0) + (n.window_blur ?? 0) + (n.paste ?? 0) >= LOOKED_AWAY_FLAG;
}

function every(ms, fn) {
  let stopped = false;
  let timer = null;
  const tick = async () => {
    if (stopped) return;
    try { await fn(); } finally { if (!stopped) timer = setTimeout(tick, ms); }
  };
  cleanups.push(() => { stopped = true; clearTimeout(timer); });
  return tick();
}

async function copyText(text, input) {
  try {
    await navigator.clipboard.writeText(text);
  } catch {
    // The clipboard API needs a secure context; selecting the text still lets the experimenter copy it.
    input?.select();
    document.execCommand?.("copy");
  }
  toast("Participant link copied");
}

// ---------------------------------------------------------------- routing

// Who is behind the token ({name, role}), asked once per token: the topbar names them, owners see Accounts.
let person = null;
let personToken = null;
async function whoami() {
  const token = api.token();
  if (personToken !== token) {
    person = await api.whoami();
    personToken = token;
  }
  meLink.textContent = `${person.name} (${person.role})`;
  meLink.hidden = false;
  return person;
}

let routing = null; // the route being shown
let routeAgain = false; // the address or the login changed while it was: show the route once more afterwards

/** Show the view for the current address. One at a time: a view that finished loading after a later one (a login
 * answered after the address changed) would otherwise replace it, and leave its timers running. */
async function route() {
  if (routing) {
    routeAgain = true;
    return routing;
  }
  routing = (async () => {
    do {
      routeAgain = false;
      await showRoute();
    } while (routeAgain);
  })();
  try {
    await routing;
  } finally {
    routing = null;
  }
}

async function showRoute() {
  for (const stop of cleanups) stop();
  cleanups = [];
  const token = api.token();
  logoutButton.hidden = !token;
  meLink.hidden = true;
  if (!token) return loginView();
  const parts = location.hash.replace(/^#\/?/, "").split("/").filter(Boolean).map(decodeURIComponent);
  try {
    const me = await whoami();
    if (parts[0] === "new") return await newStudyView();
    if (parts[0] === "audit") return await auditView();
    if (parts[0] === "accounts") return await accountsView(me);
    if (parts[0] === "account") return accountView(me);
    if (parts[0] === "study" && parts[2] === "p") return await participantView(parts[1], Number(parts[3]));
    if (parts[0] === "study" && parts[2] === "edit") return await editStudyView(parts[1]);
    if (parts[0] === "study" && parts[2] === "prolific") return await prolificView(parts[1]);
    if (parts[0] === "study") return await studyView(parts[1]);
    return await studiesView(me);
  } catch (error) {
    if (error instanceof api.ApiError && error.status === 401) {
      api.clearToken();
      return loginView("The server no longer accepts this token (it may have restarted with another one, or the "
        + "login expired or was ended). Log in again.");
    }
    app.replaceChildren(errorBox(error), h("p", {}, h("a", { href: "#/" }, "Back to the studies")));
  }
}

logoutButton.addEventListener("click", () => {
  api.clearToken();
  person = personToken = null;
  location.hash = "#/";
  route();
});
window.addEventListener("hashchange", route);
route();

// ---------------------------------------------------------------- log in

function loginView(message = null) {
  setCrumbs();
  const status = h("div", { id: "login-message" }, message ? errorBox(message) : null);
  const name = h("input", { type: "text", id: "login-name", name: "username", autocomplete: "username", required: true });
  const password = h("input", { type: "password", id: "login-password", name: "password",
    autocomplete: "current-password", required: true });
  const personal = h("form", { class: "card login", id: "password-login", onsubmit: async (event) => {
    event.preventDefault();
    status.replaceChildren(h("p", { class: "muted" }, "Checking…"));
    try {
      const session = await api.login(name.value.trim(), password.value);
      api.setToken(session.token);
      toast(`Logged in as ${session.name} (${session.role}) until ${when(session.expires_at)}`);
      route();
    } catch (error) {
      status.replaceChildren(errorBox(error instanceof api.ApiError && error.status === 401
        ? "Login failed: wrong name or password." : `Login failed: ${error.detail ?? error}`));
    }
  } },
  h("h1", {}, "Experimenter login"),
  h("p", { class: "muted" }, "Log in with the name and password the study's owner gave you. The session lasts 12 hours "
    + "and is kept in this tab only."),
  h("label", { for: "login-name" }, "Name"), name,
  h("label", { for: "login-password" }, "Password"), password,
  h("button", { type: "submit", class: "primary" }, "Log in"),
  status);
  const input = h("input", { type: "password", id: "token", name: "token", autocomplete: "off",
    required: true, placeholder: "experimenter token" });
  const byToken = h("form", { class: "card login", id: "token-login", onsubmit: async (event) => {
    event.preventDefault();
    status.replaceChildren(h("p", { class: "muted" }, "Checking…"));
    try {
      await api.checkToken(input.value.trim());
      api.setToken(input.value.trim());
      route();
    } catch (error) {
      const text = error instanceof api.ApiError && error.status === 401
        ? `Login failed: the server refused this token (${error.detail}). The dashboard needs the experimenter token `
          + "the server was started with, or a personal API token; participant links and tokens do not give access."
        : `Login failed: ${error.detail ?? error}`;
      status.replaceChildren(errorBox(text));
    }
  } },
  h("h2", {}, "Or with a token"),
  h("p", { class: "muted" }, "The server's experimenter key (TABLETEACH_EXPERIMENTER_TOKEN, or the one "
    + "`tableteach serve --dev` printed), or a personal API token. It is kept in this tab only."),
  h("label", { for: "token" }, "Token"), input,
  h("button", { type: "submit" }, "Log in with the token"));
  app.replaceChildren(personal, byToken);
  name.focus();
}

// ---------------------------------------------------------------- audit log

async function auditView() {
  setCrumbs({ text: "Studies", href: "#/" }, { text: "Audit log" });
  const entries = await api.audit();
  const saveCsv = async () => {
    try {
      const { filename, blob } = await api.auditCsv();
      saveBlob(filename, blob);
    } catch (error) {
      toast(`Download failed: ${error.detail ?? error}`, "error");
    }
  };
  const rows = entries.map((e) => h("tr", {},
    h("td", {}, when(e.at)), h("td", {}, e.actor), h("td", {}, e.role),
    h("td", {}, h("code", {}, `${e.method} ${e.path}`)),
    h("td", {}, e.status < 400 ? pill(`done ${e.status}`, "good") : pill(`refused ${e.status}`, "bad")),
    h("td", {}, e.client)));
  app.replaceChildren(
    h("div", { class: "page-head" }, h("h1", {}, "Audit log"),
      h("button", { id: "audit-csv", onclick: saveCsv }, "Download audit.csv")),
    h("p", { class: "muted" }, "Every change an experimenter made or tried: who, what, when and from which address "
      + "(newest first; the last 500 here, all of them in the download)."),
    entries.length
      ? h("div", { class: "table-scroll" }, h("table", { class: "data", id: "audit" },
        h("thead", {}, h("tr", {}, ["When", "Who", "Role", "What", "Result", "From"].map((c) => h("th", {}, c)))),
        h("tbody", {}, rows)))
      : h("p", { class: "card muted" }, "No changes yet."));
}

// ---------------------------------------------------------------- studies

async function studiesView(me) {
  setCrumbs({ text: "Studies" });
  const showArchived = location.hash.includes("archived");
  const studies = await api.listStudies(showArchived);
  const rows = studies.map((s) => h("tr", { class: "clickable", onclick: () => { location.hash = `#/study/${encodeURIComponent(s.id)}`; } },
    h("td", {}, h("a", { href: `#/study/${encodeURIComponent(s.id)}` }, s.name), s.pilot ? pill("pilot") : null),
    h("td", {}, h("code", {}, s.id)),
    h("td", {}, pill(s.status), s.archived_at ? pill("archived", "muted") : null),
    h("td", {}, s.tasks.map((t) => t.key).join(", ")),
    h("td", {}, s.conditions.join(", "), h("span", { class: "muted" }, ` (${s.assignment})`)),
    h("td", {}, when(s.created_at))));
  app.replaceChildren(
    h("div", { class: "page-head" }, h("h1", {}, "Studies"),
      h("div", { class: "row" }, h("a", { href: showArchived ? "#/" : "#/?archived", id: "toggle-archived" },
        showArchived ? "Hide archived studies" : "Show archived studies"),
      h("a", { class: "button", href: "#/audit", id: "audit-link" }, "Audit log"),
      me.role === "owner" ? h("a", { class: "button", href: "#/accounts", id: "accounts-link" }, "Accounts") : null,
      h("a", { class: "button primary", href: "#/new", id: "new-study" }, "New study"))),
    studies.length
      ? h("div", { class: "table-scroll" }, h("table", { class: "data", id: "studies" },
        h("thead", {}, h("tr", {}, ["Name", "Id", "Status", "Tasks", "Conditions", "Created"].map((c) => h("th", {}, c)))),
        h("tbody", {}, rows)))
      : h("p", { class: "card muted" }, "No studies yet. Create one to get a participant link."));
}

// ---------------------------------------------------------------- new study

async function newStudyView() {
  setCrumbs({ text: "Studies", href: "#/" }, { text: "New study" });
  const choices = await api.studyChoices();
  app.replaceChildren(studyFormView({ choices, onSaved: (study) => {
    toast(`Study ${study.id} created (draft): open it to let participants join`);
    location.hash = `#/study/${encodeURIComponent(study.id)}`;
  } }));
}

async function editStudyView(studyId) {
  const [choices, study] = await Promise.all([api.studyChoices(), api.getStudy(studyId)]);
  setCrumbs({ text: "Studies", href: "#/" }, { text: study.name, href: `#/study/${encodeURIComponent(studyId)}` },
    { text: "Edit" });
  app.replaceChildren(studyFormView({ choices, study, onSaved: (saved) => {
    toast("Changes saved");
    location.hash = `#/study/${encodeURIComponent(saved.id)}`;
  } }));
}

// ---------------------------------------------------------------- one study

async function studyView(studyId) {
  let study = await api.getStudy(studyId);
  setCrumbs({ text: "Studies", href: "#/" }, { text: study.name });
  const dropoutKey = `tableteach.dropoutMinutes.${studyId}`;
  const head = h("div", { class: "page-head" });
  const liveBox = h("div", { id: "live" });
  const curvesBox = h("div", { id: "curves", class: "curves" }, h("p", { class: "muted" }, "Loading curves…"));
  const statsBox = h("div", { id: "statistics-body" }, h("p", { class: "muted" }, "Loading statistics…"));
  const finishedOnly = h("input", { type: "checkbox", id: "finished-only" });
  const dropoutInput = h("input", { type: "number", id: "dropout-minutes", min: 1, step: 1, size: 5,
    value: localStorage.getItem(dropoutKey) ?? "" });
  const updated = h("span", { class: "muted small" });

  const renderHead = () => {
    const linkInput = h("input", { id: "join-link", readonly: true, value: api.joinLink(study.id), class: "grow" });
    const prolific = h("input", { type: "checkbox", id: "prolific-link", onchange: () => {
      linkInput.value = api.joinLink(study.id, { prolific: prolific.checked });
    } });
    const toggle = study.status === "open"
      ? h("button", { id: "close-study", onclick: () => setStatus(api.closeStudy,
        "Close this study? New participants can no longer join (the link shows that the study is closed); those "
        + "under way may finish. You can reopen it later.") }, "Close study")
      : h("button", { id: "open-study", class: "primary", onclick: () => setStatus(api.openStudy,
        `${study.status === "draft" ? "Open" : "Reopen"} this study? Anyone with the link can join at once`
        + (study.status === "draft" ? "; its tasks, conditions and questionnaire can no longer be edited (clone it for "
          + "a changed copy)." : ".")) },
      study.status === "draft" ? "Open study" : "Reopen study");
    head.replaceChildren(
      h("div", {}, h("h1", {}, study.name, " ", pill(study.status), study.pilot ? pill("pilot") : null),
        h("p", { class: "muted" }, h("code", {}, study.id), " · ",
          study.tasks.map((t) => t.name).join(" → "), " · conditions ", study.conditions.join(", "),
          ` (${study.assignment})`, ` · ${study.n_practice} practice, ${study.n_demonstrations} demonstrations, `,
          `${study.n_queries} queries, ${study.n_tests} tests · prior ${study.prior}, ${study.criterion}`)),
      h("div", { class: "link-box" }, h("label", { for: "join-link" }, "Participant link"),
        h("div", { class: "row" }, linkInput,
          h("button", { id: "copy-link", onclick: () => copyText(linkInput.value, linkInput) }, "Copy"), toggle),
        h("label", { class: "inline small" }, prolific, "with Prolific placeholders"),
        h("div", { class: "row small study-actions" },
          h("a", { class: "button", id: "edit-study", href: `#/study/${encodeURIComponent(study.id)}/edit` }, "Edit"),
          h("button", { id: "clone-study", onclick: cloneStudy }, "Clone"),
          h("button", { id: "reset-pilot", onclick: resetPilot }, "Reset pilot…"),
          h("a", { class: "button", id: "open-prolific", href: `#/study/${encodeURIComponent(study.id)}/prolific` },
            "Prolific: reconcile and bonuses"),
          study.archived_at
            ? h("button", { id: "unarchive-study", onclick: () => archive(false) }, "Unarchive")
            : h("button", { id: "archive-study", onclick: () => archive(true) }, "Archive…"),
          h("button", { id: "delete-study", class: "erase", onclick: deleteStudy }, "Delete…")),
        codesNote()));
  };
  const codesNote = () => (study.completion_code
    ? h("p", { class: "small muted", id: "codes-note" }, OUTCOME_CODES.filter(([name]) => study[name])
      .flatMap(([name, label], i) => [i ? " · " : "", `${label}: `, h("code", {}, study[name])]),
      study.screened_out_code ? [" · other screened-out outcomes: ", h("code", {}, study.screened_out_code)] : null,
      study.timeout_minutes ? ` · time-out after ${study.timeout_minutes} min` : null)
    : h("p", { class: "small warn" }, "No completion code set: each participant gets their own code, which Prolific cannot check. ",
      h("a", { href: `#/study/${encodeURIComponent(study.id)}/edit` }, "Set the codes")));
  const archive = async (archived) => {
    if (archived && !confirm("Archive this study? It is hidden from the list of studies (and closed if open); "
      + "nothing of it is deleted, and you can unarchive it.")) return;
    try {
      study = await (archived ? api.archiveStudy(study.id) : api.unarchiveStudy(study.id));
      toast(archived ? "Study archived" : "Study back in the list");
      renderHead();
    } catch (error) {
      toast(error.detail ?? String(error), "error");
    }
  };
  const deleteStudy = async () => {
    if (!confirm(`Delete the study "${study.name}" for good? This is possible only while it has no participants.`)) return;
    try {
      await api.deleteStudy(study.id);
      toast("Study deleted");
      location.hash = "#/";
    } catch (error) {
      toast(error.detail ?? String(error), "error");
    }
  };
  const cloneStudy = async () => {
    try {
      const copy = await api.cloneStudy(study.id);
      toast(`Draft copy ${copy.id} created`);
      location.hash = `#/study/${encodeURIComponent(copy.id)}/edit`;
    } catch (error) {
      toast(error.detail ?? String(error), "error");
    }
  };
  const resetPilot = async () => {
    if (!confirm("Erase every pilot participant of this study? Their data are deleted for good; the other participants are not touched.")) return;
    try {
      const answer = await api.resetPilot(study.id);
      toast(`Pilot reset: ${answer.erased.length} pilot participant(s) erased`);
      poll();
    } catch (error) {
      toast(error.detail ?? String(error), "error");
    }
  };
  const setStatus = async (call, question) => {
    if (!confirm(question)) return;
    try {
      study = await call(study.id);
      toast(`Study is now ${study.status}`);
      renderHead();
    } catch (error) {
      toast(error.detail ?? String(error), "error");
    }
  };
  renderHead();

  const includePilot = h("input", { type: "checkbox", id: "include-pilot", checked: study.pilot });
  const downloads = h("div", { class: "row", id: "downloads" }, api.EXPORTS.map((name) => h("button", {
    "data-export": name.replace(/\.(csv|zip)$/, ""), class: name.endsWith(".zip") ? "primary" : "",
    onclick: () => download(study.id, name, includePilot.checked) }, name)));

  app.replaceChildren(head,
    h("section", { class: "card" },
      h("div", { class: "section-head" }, h("h2", {}, "Participants"),
        h("div", { class: "row small" }, h("label", { class: "inline", for: "dropout-minutes" }, "Flag as dropout after"),
          dropoutInput, h("span", {}, "min inactive"), updated)),
      liveBox),
    h("section", { class: "card", id: "statistics" }, h("h2", {}, "Study statistics"), statsBox),
    h("section", { class: "card" },
      h("div", { class: "section-head" }, h("h2", {}, "Learning curves"),
        h("div", { class: "row small" }, h("label", { class: "inline" }, finishedOnly, "completed participants only"),
          h("label", { class: "inline" }, includePilot, "include pilot participants"))),
      h("p", { class: "muted small" }, "After each learning step (0: the prior; then each demonstration or assessed query): ",
        "median expected similarity to the ground truth (band: interquartile range, thin lines: participants) and mean entropy of the belief."),
      curvesBox),
    h("section", { class: "card" }, h("h2", {}, "Downloads"),
      h("p", { class: "muted small" }, "exports.zip holds every CSV, codebook.csv (what each column means) and the ",
        "study definition. Pilot participants are left out unless \"include pilot participants\" is ticked."), downloads));

  let signature = null;
  const refreshCurves = async () => {
    try {
      renderCurves(curvesBox, await api.curves(study.id, finishedOnly.checked, includePilot.checked), study);
      renderStatistics(statsBox, await api.statistics(study.id, includePilot.checked));
    } catch (error) {
      curvesBox.replaceChildren(errorBox(error));
    }
  };
  finishedOnly.addEventListener("change", refreshCurves);
  includePilot.addEventListener("change", refreshCurves);
  const poll = async () => {
    const minutes = Number(dropoutInput.value) > 0 ? Number(dropoutInput.value) : null;
    const data = await api.live(study.id, minutes);
    if (!dropoutInput.value) dropoutInput.placeholder = String(data.dropout_minutes);
    renderLive(liveBox, data, study, poll);
    updated.textContent = `updated ${new Date().toLocaleTimeString()}`;
    const now = data.participants.map((p) => `${p.participant_id}:${p.n_events}`).join(",");
    if (now !== signature) {
      signature = now;
      await refreshCurves();
    }
  };
  dropoutInput.addEventListener("change", () => {
    if (Number(dropoutInput.value) > 0) localStorage.setItem(dropoutKey, dropoutInput.value);
    else localStorage.removeItem(dropoutKey);
    poll();
  });
  await every(POLL_MS, async () => {
    try {
      await poll();
    } catch (error) {
      if (error instanceof api.ApiError && error.status === 401) { route(); return; }
      updated.textContent = `update failed: ${error.detail ?? error}`;
    }
  });
}

function progressText(p, study) {
  const index = p.step?.task_index ?? p.task_index;
  if (p.stage === "task" && p.step) {
    const step = p.step.kind === "done" ? "finishing" : `${p.step.kind} ${p.step.index + 1}/${p.step.total}`;
    const position = p.task_order ? p.task_order.indexOf(index) : index;
    const name = study?.tasks[index]?.name ?? `task ${index + 1}`;
    return `${name} (${position + 1}/${p.n_tasks ?? study?.tasks.length}) · ${step}`;
  }
  return p.stage.replace("_", " ");
}

/** The funnel, the completion times and the condition x task-order cells (GET .../statistics). */
function renderStatistics(box, data) {
  const top = Math.max(1, ...data.funnel.map((f) => f.n));
  const funnel = h("table", { class: "data funnel", id: "funnel" },
    h("caption", { class: "small muted" }, "How far participants got"),
    h("tbody", {}, data.funnel.map((f) => h("tr", {}, h("th", { scope: "row" }, f.label),
      h("td", { class: "num" }, f.n),
      h("td", { class: "bar-cell" }, h("meter", { min: 0, max: top, value: f.n, "aria-label": `${f.label}: ${f.n} of ${top}` }))))));
  const t = data.completion_seconds;
  const times = t.n
    ? h("p", { id: "completion-times" }, `Completion time of ${t.n} participant(s): median ${duration(t.median)}`,
      t.quartiles ? ` (quartiles ${duration(t.quartiles[0])} – ${duration(t.quartiles[2])})` : "",
      `, fastest ${duration(t.min)}, slowest ${duration(t.max)}.`)
    : h("p", { class: "muted", id: "completion-times" }, "Nobody has completed the study yet.");
  const cells = data.cells.length
    ? h("table", { class: "data", id: "cells" }, h("caption", { class: "small muted" }, "Participants per condition and task order"),
      h("thead", {}, h("tr", {}, ["Condition", "Task order", "Participants"].map((c) => h("th", { scope: "col" }, c)))),
      h("tbody", {}, data.cells.map((c) => h("tr", {}, h("td", {}, c.condition), h("td", {}, c.tasks.join(" → ")),
        h("td", { class: "num" }, c.n)))))
    : h("p", { class: "muted" }, "No participants yet.");
  box.replaceChildren(h("div", { class: "chart-row" }, funnel, h("div", {}, times, cells)));
}

function duration(seconds) {
  if (seconds === null || seconds === undefined) return "–";
  const m = Math.floor(seconds / 60);
  return m >= 60 ? `${Math.floor(m / 60)} h ${m % 60} min` : `${m} min ${Math.round(seconds % 60)} s`;
}

const END_REASONS = { declined_consent: "declined consent", withdrew: "withdrew", comprehension: "failed the quiz",
  timeout: "timed out" };
const OUTCOME_NAMES = { completed: "completed", attention: "failed an attention check", ...END_REASONS };

/** The code a participant was shown and why (their outcome), e.g. "C2SCREEN (timed out)". */
function codeCell(p) {
  if (!p.outcome) return h("span", { class: "muted" }, "–");
  const why = h("span", { class: "small muted" }, ` ${OUTCOME_NAMES[p.outcome] ?? p.outcome}`);
  return [p.completion_code ? h("code", {}, p.completion_code) : h("span", { class: "muted" }, "no code"), why];
}

const RESTORABLE = ["timeout", "comprehension", "declined_consent"];
const HELPABLE_WORDS = {
  instructions: "Their instructions are marked as read.", quiz: "They are let past the comprehension quiz.",
  task: "Their current task ends (what they taught so far is kept); the next task or the questionnaire follows.",
  questionnaire: "Their questionnaire ends with the answers given so far, and they are done." };
const HELPABLE = Object.keys(HELPABLE_WORDS);

/** Restore or help on one participant after a confirmation; the page shows the result (both are logged). */
async function assist(call, studyId, p, question) {
  if (!confirm(`${question}\n\nThis is recorded in the participant's event log.`)) return;
  try {
    const row = await call(studyId, p.participant_id);
    toast(`Participant #${p.participant_id} is now at the ${row.stage} stage`);
    route();
  } catch (error) {
    toast(error.detail ?? String(error), "error");
  }
}

async function erase(study, p, after) {
  if (!confirm(`Erase participant #${p.participant_id}? Their events, answers, beliefs and robot recordings are deleted `
    + "for good; an audit entry without personal data is kept.")) return;
  try {
    await api.eraseParticipant(study.id, p.participant_id);
    toast(`Participant #${p.participant_id} erased`);
    after();
  } catch (error) {
    toast(error.detail ?? String(error), "error");
  }
}

function renderLive(box, data, study, refresh) {
  const ps = data.participants;
  const count = (pred) => ps.filter(pred).length;
  const summary = h("div", { class: "stats" },
    [["participants", ps.length], ["active", count((p) => p.status === "active")], ["idle", count((p) => p.status === "idle")],
      ["done", count((p) => p.status === "done")], ["withdrawn", count((p) => p.status === "withdrawn")],
      ["screened out", count((p) => p.status === "screened_out")], ["dropouts", count((p) => p.dropout)],
      ["attention failed", count((p) => p.attention_failed)]].map(([label, n]) => h("div", { class: `stat stat-${label}` }, h("b", {}, n), label)));
  if (!ps.length) {
    box.replaceChildren(summary, h("p", { class: "muted" }, study.status === "open"
      ? "No participants yet: share the link above." : "No participants yet. Open the study to let participants join."));
    return;
  }
  const rows = ps.map((p) => {
    const href = `#/study/${encodeURIComponent(study.id)}/p/${p.participant_id}`;
    return h("tr", { class: `clickable ${p.dropout ? "dropout" : ""}`, "data-participant": p.participant_id,
      onclick: (e) => { if (e.target.tagName !== "A") location.hash = href; } },
    h("td", {}, h("a", { href }, `#${p.participant_id}`), p.pilot ? pill("pilot") : null),
    h("td", {}, p.condition),
    h("td", {}, progressText(p, study)),
    h("td", {}, pill(p.status.replace("_", " "), p.status), p.dropout ? pill("dropout") : null,
      p.attention_failed ? pill("attention failed", "flag") : null, consistencyPill(p),
      lookedAway(p) ? h("span", { class: "pill flag", title: signalsText(p) }, "looked away") : null,
      p.end_reason && p.end_reason !== "withdrew" ? h("span", { class: "small muted" }, ` ${END_REASONS[p.end_reason] ?? p.end_reason}`) : null),
    h("td", { class: "num", title: `joined ${when(p.created_at)}` }, duration(p.elapsed_seconds)),
    h("td", { title: when(p.last_activity_at) }, ago(p.last_activity_at)),
    h("td", { class: "num" }, p.n_events),
    h("td", {}, p.prolific_pid ?? h("span", { class: "muted" }, "–")),
    h("td", { class: "code-cell" }, codeCell(p)),
    h("td", {}, h("button", { class: "ghost small erase", title: "erase this participant's data",
      onclick: (e) => { e.stopPropagation(); erase(study, p, refresh); } }, "Erase")));
  });
  box.replaceChildren(summary, h("table", { class: "data", id: "participants" },
    h("thead", {}, h("tr", {}, ["Participant", "Condition", "Step", "Status", "Elapsed", "Last activity", "Events", "External id", "Completion", ""]
      .map((c) => h("th", {}, c)))),
    h("tbody", {}, rows)));
}

function renderCurves(box, data, study) {
  const colors = Object.fromEntries(study.conditions.map((c, i) => [c, PALETTE[i % PALETTE.length]]));
  const blocks = data.tasks.map((task) => {
    if (!task.participants.length) return h("div", { class: "task-curves" }, h("h3", {}, task.name), h("p", { class: "muted" }, "No data yet."));
    const simSeries = [];
    const entSeries = [];
    for (const p of task.participants) {
      simSeries.push({ name: `#${p.participant_id}`, color: colors[p.condition], faint: true,
        points: p.similarity.map((y, x) => ({ x, y })) });
    }
    for (const c of task.conditions) {
      const label = `${c.condition} (n=${c.points[0]?.n ?? 0})`;
      simSeries.push({ name: label, color: colors[c.condition],
        band: c.points.map((pt) => ({ x: pt.step, lo: pt.q1_similarity, hi: pt.q3_similarity })),
        points: c.points.map((pt) => ({ x: pt.step, y: pt.median_similarity,
          label: `${c.condition}, step ${pt.step}: median similarity ${num(pt.median_similarity)} (n=${pt.n_similarity})` })) });
      entSeries.push({ name: label, color: colors[c.condition],
        points: c.points.map((pt) => ({ x: pt.step, y: pt.mean_entropy,
          label: `${c.condition}, step ${pt.step}: mean entropy ${num(pt.mean_entropy)} nats (n=${pt.n})` })) });
    }
    const charts = [];
    if (task.has_ground_truth) {
      charts.push(lineChart(simSeries, { title: "Similarity to the ground truth (median)", xLabel: "learning step",
        yLabel: "similarity", yMin: 0, yMax: 1, width: 520, height: 230 }));
    }
    charts.push(lineChart(entSeries, { title: "Belief entropy (mean)", xLabel: "learning step", yLabel: "entropy (nats)", yMin: 0,
      width: 520, height: 230 }));
    return h("div", { class: "task-curves", "data-task": task.task_index }, h("h3", {}, task.name),
      task.has_ground_truth ? null : h("p", { class: "muted small" }, "Ground truth unknown: no similarity curve."),
      h("div", { class: "chart-row" }, charts));
  });
  box.replaceChildren(...blocks);
}

async function download(studyId, name, includePilot = false) {
  try {
    const { filename, blob } = await api.exportCsv(studyId, name, includePilot);
    saveBlob(filename, blob);
  } catch (error) {
    toast(`Download failed: ${error.detail ?? error}`, "error");
  }
}

// ---------------------------------------------------------------- one participant

async function participantView(studyId, participantId) {
  const [study, data] = await Promise.all([api.getStudy(studyId), api.history(studyId, participantId)]);
  setCrumbs({ text: "Studies", href: "#/" }, { text: study.name, href: `#/study/${encodeURIComponent(studyId)}` },
    { text: `Participant #${participantId}` });
  const p = data.participant;
  const facts = [["Condition", p.condition], ["Stage", p.stage], ["Joined", when(p.created_at)],
    ["Last activity", `${ago(p.last_activity_at)}`], ["Finished", when(p.finished_at)], ["Events", p.n_events],
    ["External id", p.prolific_pid ?? "–"], ["Completion code", p.outcome ? `${p.completion_code ?? "no code"} (${OUTCOME_NAMES[p.outcome] ?? p.outcome})` : "–"], ["Seed", p.seed],
    ["Elapsed", duration(p.elapsed_seconds)], ["Task order", (p.task_order ?? study.tasks.map((_, i) => i)).map((i) => study.tasks[i].name).join(" → ")],
    ["Left early", p.end_reason ? END_REASONS[p.end_reason] ?? p.end_reason : "–"],
    ["Attention checks", p.attention_failed ? "failed" : "passed or none"],
    ["Attention telemetry", signalsText(p)]];
  app.replaceChildren(
    h("div", { class: "page-head" }, h("h1", {}, `Participant #${p.participant_id} `, pill(p.status), p.pilot ? pill("pilot") : null),
      h("div", { class: "row" }, h("button", { onclick: () => route() }, "Refresh"),
        RESTORABLE.includes(p.end_reason) ? h("button", { id: "restore-participant", onclick: () => assist(
          api.restoreParticipant, studyId, p, `Restore participant #${p.participant_id}? They continue where they were `
          + "(a failed quiz gets fresh attempts) and are no longer screened out; their code is withdrawn.") },
        "Restore") : null,
        HELPABLE.includes(p.stage) ? h("button", { id: "help-participant", onclick: () => assist(
          api.helpParticipant, studyId, p, `Help participant #${p.participant_id} on? ${HELPABLE_WORDS[p.stage]}`) },
        "Help on to the next stage") : null,
        h("button", { class: "erase", id: "erase-participant", onclick: () => erase(study, p, () => {
          location.hash = `#/study/${encodeURIComponent(studyId)}`;
        }) }, "Erase this participant's data"))),
    h("dl", { class: "card facts" }, facts.flatMap(([k, v]) => [h("dt", {}, k), h("dd", {}, v === null || v === undefined ? "–" : String(v))])),
    ...data.tasks.map((task) => taskSection(task, studyId, participantId)),
    data.tasks.length ? whatIfSection(studyId, participantId) : h("p", { class: "card muted" }, "This participant has not started a task yet."),
    data.questionnaire.length ? h("section", { class: "card" }, h("h2", {}, "Questionnaire"),
      h("table", { class: "data", id: "answers" }, h("tbody", {}, data.questionnaire.map((a) =>
        h("tr", {}, h("td", {}, a.text ?? a.item_id), h("td", { class: "answer" }, a.answer === null || a.answer === undefined ? "(no answer)" : String(a.answer))))))) : null,
    h("details", { class: "card" }, h("summary", {}, `Event log (${data.events.length} events)`),
      h("table", { class: "data small", id: "events" },
        h("thead", {}, h("tr", {}, ["#", "Time", "Kind", "Task", "Step", "Details"].map((c) => h("th", {}, c)))),
        h("tbody", {}, data.events.map((e) => h("tr", {}, h("td", {}, e.seq), h("td", {}, when(e.created_at)), h("td", {}, e.kind),
          h("td", {}, e.task_index === null ? "" : e.task_index + 1),
          h("td", {}, e.step_kind ? `${e.step_kind} ${e.step_index + 1}` : ""),
          h("td", { class: "payload" }, eventDetails(e))))))));
}

function eventDetails(e) {
  const pl = e.payload;
  if (e.kind === "place") return `chose the ${pretty(pl.object)}`;
  if (e.kind === "placed") return `robot placed the ${pretty(pl.object)}; in place: ${(pl.labels ?? []).map(pretty).join(", ") || "nothing"}`;
  if (e.kind === "assessment") return pl.acceptable === null ? "no verdict" : pl.acceptable ? "acceptable" : "unacceptable";
  if (e.kind === "execution_started") return `robot: ${(pl.events ?? []).map(pretty).join(", ")}`;
  if (e.kind === "task_started") return `${pl.task}, ${pl.protocol}, seed ${pl.seed}`;
  if (e.kind === "completed") return `code ${pl.completion_code}`;
  return "";
}

function taskSection(task, studyId, participantId) {
  const steps = task.steps;
  const byStep = Object.fromEntries(task.executions.filter((x) => x.learning_step).map((x) => [x.learning_step, x]));
  const stepName = (k) => (k === 0 ? "the prior" : `${KIND_NAMES[byStep[k]?.kind ?? steps[k].record.kind].toLowerCase()} ${(byStep[k]?.index ?? 0) + 1}`);
  const size = { width: 330, height: 190 };
  const charts = [lineChart([{ name: "entropy", color: PALETTE[0],
    points: steps.map((s) => ({ x: s.step, y: s.entropy, label: `after ${stepName(s.step)}: ${num(s.entropy)} nats` })) }],
  { title: "Belief entropy (nats)", xLabel: "learning step", yMin: 0, legend: false, ...size })];
  if (task.ground_truth) {
    charts.push(lineChart([
      { name: "expected", color: PALETTE[2], points: steps.map((s) => ({ x: s.step, y: s.similarity, label: `after ${stepName(s.step)}: expected ${num(s.similarity)}` })) },
      { name: "MAP", color: PALETTE[1], dashed: true, points: steps.map((s) => ({ x: s.step, y: s.map_similarity, label: `after ${stepName(s.step)}: MAP ${num(s.map_similarity)}` })) },
    ], { title: "Similarity to the ground truth", xLabel: "learning step", yMin: 0, yMax: 1, ...size }));
  }

  const inspector = h("div", { class: "inspector" });
  const replayBox = h("div", { class: "replay-box" });
  const beliefBox = h("div", {});
  const stepButtons = h("div", { class: "segmented", role: "group", "aria-label": "learning step" });
  inspector.append(replayBox, h("div", { class: "inspector-head" }, h("h3", {}, "Belief after step"), stepButtons), beliefBox);
  const rows = [];
  const select = (k) => {
    for (const b of stepButtons.children) b.classList.toggle("selected", Number(b.dataset.step) === k);
    for (const r of rows) r.classList.toggle("selected", Number(r.dataset.learningStep) === k);
    beliefBox.replaceChildren(beliefBlock(steps[k], task, stepName(k)));
  };
  steps.forEach((s) => stepButtons.append(h("button", { type: "button", class: "small", "data-step": s.step,
    title: `belief after ${stepName(s.step)}`, onclick: () => select(s.step) }, String(s.step))));

  const openReplay = async (x) => {
    replayBox.replaceChildren(h("p", { class: "muted" }, "Loading replay…"));
    try {
      const data = await api.replay(studyId, participantId, x);
      replayBox.replaceChildren(h("div", { class: "inspector-head" },
        h("h3", {}, `Replay: ${KIND_NAMES[x.kind].toLowerCase()}${x.kind === "practice" ? "" : ` ${x.index + 1}`}`),
        h("button", { type: "button", class: "small ghost", onclick: () => replayBox.replaceChildren() }, "Close")),
      replayPlayer(data));
    } catch (error) {
      replayBox.replaceChildren(errorBox(error));
    }
  };
  for (const x of task.executions) {
    const row = h("tr", { class: `exec ${x.kind} ${x.learning_step ? "clickable" : ""}`, "data-kind": x.kind, "data-index": x.index,
      "data-learning-step": x.learning_step ?? "", onclick: (event) => {
        if (x.learning_step && event.target.tagName !== "BUTTON") select(x.learning_step);
      } },
    h("td", { title: `by the ${x.by}` }, h("span", { class: `dot-kind ${x.kind}` }), h("b", {}, KIND_NAMES[x.kind]),
      x.kind === "practice" ? "" : ` ${x.index + 1}`),
    h("td", {}, traceChips(x.trace)),
    h("td", {}, verdict(x)),
    h("td", { class: "num small", title: "the robot's probability that its execution is acceptable, before the verdict" },
      x.p_acceptable === null ? "" : pct(x.p_acceptable)),
    h("td", { class: "num muted small" }, x.learning_step ?? "–"),
    h("td", {}, h("button", { type: "button", class: "small", disabled: !x.trace, "data-replay": `${x.kind}-${x.index}`,
      onclick: () => { if (x.learning_step) select(x.learning_step); openReplay(x); } }, "Replay")));
    rows.push(row);
  }
  select(steps.length - 1);

  const current = task.step.kind === "done" ? pill("finished", "done") : pill(`at ${task.step.kind} ${task.step.index + 1} of ${task.step.total}`, "active");
  return h("section", { class: "card task", "data-task": task.task_index },
    h("div", { class: "section-head" }, h("h2", {}, task.name ?? `Task ${task.task_index + 1}`, current)),
    task.ground_truth
      ? h("p", { class: "truth small" }, h("b", {}, "Ground truth "), h("code", { class: "formula" }, task.ground_truth),
        h("span", { class: "muted" }, ` — ${task.ground_truth_description}`))
      : h("p", { class: "muted small" }, "Ground truth unknown: no similarity."),
    consistencyNote(task),
    h("div", { class: "task-grid" },
      h("div", {}, h("div", { class: "chart-row" }, charts),
        h("table", { class: "data executions" },
          h("thead", {}, h("tr", {}, ["Step", "Trace", "Label", "P(acc.)", "Belief", ""].map((c) => h("th", {}, c)))),
          h("tbody", {}, rows))),
      inspector));
}

function traceChips(trace) {
  if (!trace) return h("span", { class: "muted small" }, "no trace yet");
  const out = [];
  for (let k = 1; k < trace.length; k++) {
    const added = trace[k].filter((o) => !trace[k - 1].includes(o));
    const removed = trace[k - 1].filter((o) => !trace[k].includes(o));
    const text = [...added.map(pretty), ...removed.map((o) => `−${pretty(o)}`)].join(" + ") || "(no change)";
    out.push(h("span", { class: "chip" }, text));
  }
  return h("span", { class: "trace" }, out.length ? out : h("span", { class: "muted small" }, "nothing placed"));
}

function verdict(x) {
  if (x.kind === "practice") return pill("practice", "neutral");
  if (x.kind === "demonstration") return pill(x.status === "finished" ? "acceptable" : "in progress", x.status === "finished" ? "good" : "neutral");
  if (x.status !== "assessed") return pill(x.status === "running" ? "in progress" : "awaiting label", "neutral");
  if (x.acceptable === null) return pill("no label", "neutral");
  return x.acceptable ? pill("acceptable", "good") : pill("unacceptable", "bad");
}

function beliefBlock(step, task, name) {
  const bar = (p) => {
    const el = h("span", { class: "bar" });
    el.style.width = `${Math.max(1, 100 * p).toFixed(1)}%`; // CSSOM, allowed by the page's style-src policy
    return el;
  };
  return h("div", { class: "belief", "data-step": step.step },
    h("p", { class: "muted small" }, `After ${name}`),
    h("div", { class: "belief-stats" },
      h("div", {}, h("b", {}, num(step.entropy)), h("span", {}, "entropy (nats)")),
      task.ground_truth ? h("div", {}, h("b", {}, num(step.similarity)), h("span", {}, "expected similarity")) : null,
      task.ground_truth ? h("div", {}, h("b", {}, num(step.map_similarity)), h("span", {}, "MAP similarity")) : null),
    h("table", { class: "top" }, h("tbody", {}, step.top.map((f, i) => h("tr", {},
      h("td", { class: "bar-cell" }, bar(f.p), h("span", { class: "bar-label" }, pct(f.p))),
      h("td", {}, h("div", { class: "description" }, f.description), h("div", { class: "formula" }, f.formula)))))),
    step.learner === "exact" ? exactMarginals(step, bar) : null);
}

/** Past five objects the exact learner lists no formulas: the MAP above, then the clauses most probably in the task. */
function exactMarginals(step, bar) {
  return h("div", { class: "marginals", "data-learner": "exact" },
    h("p", { class: "muted small" }, "Past five objects the learner is the exact one: it lists no formulas, so above is "
      + "the most probable formula alone. The clauses most probably in the task:"),
    h("table", { class: "top" }, h("tbody", {}, step.marginals.map((m) => h("tr", {},
      h("td", { class: "bar-cell" }, bar(m.p), h("span", { class: "bar-label" }, pct(m.p))),
      h("td", {}, h("div", { class: "formula" }, m.clause)))))));
}

// ---------------------------------------------------------------- replay

/** Frames of a replay: [{t, poses}] from the recorded body poses, or built from the trace step by step. */
function replayFrames(data) {
  const layout = data.layout;
  if (data.source === "recording") {
    const { bodies, times, poses } = data.recording;
    return times.map((t, f) => {
      const frame = {};
      bodies.forEach((body, b) => {
        const [x, y, z, qw, qx, qy, qz] = poses[f][b];
        if (body in layout.objects) frame[body] = { x, y, z, yaw: quatYaw(qw, qx, qy, qz) };
        else if (body === "hand") frame.hand = { x, y };
        else if (body === "forearm") frame.elbow = { x, y };
      });
      return { t: t - times[0], poses: frame };
    });
  }
  // Trace only (e.g. the trace robot): each new label moves its object from Table A to its slot in 1 s.
  const names = Object.keys(layout.objects);
  const rest = {};
  for (const n of names) rest[n] = { ...layout.objects[n].start, z: 0 };
  const frames = [{ t: 0, poses: { ...rest } }];
  let t = 0;
  let height = 0;
  const state = { ...rest };
  const trace = data.trace ?? [];
  for (let k = 1; k < trace.length; k++) {
    for (const obj of trace[k].filter((o) => !trace[k - 1].includes(o) && o in layout.objects)) {
      const from = state[obj];
      const to = { ...layout.objects[obj].slot, z: ++height, placed: true };
      for (let i = 1; i <= 24; i++) {
        const a = i / 24;
        const ease = a * a * (3 - 2 * a);
        const pose = { x: from.x + (to.x - from.x) * ease, y: from.y + (to.y - from.y) * ease,
          yaw: from.yaw + (to.yaw - from.yaw) * ease, z: 100 + height, placed: i === 24 };
        state[obj] = i === 24 ? to : pose;
        frames.push({ t: t + a, poses: { ...state, hand: { x: pose.x, y: pose.y } }, step: k });
      }
      t += 1.25;
      frames.push({ t, poses: { ...state }, step: k });
    }
  }
  return frames;
}

function replayPlayer(data) {
  const view = tableView(data.layout, { width: 460, height: 300 });
  const frames = replayFrames(data);
  const duration = frames.at(-1).t || 1;
  const slider = h("input", { type: "range", min: 0, max: 1000, value: 0, class: "grow", "aria-label": "replay position" });
  const clock = h("span", { class: "muted small mono" });
  const speed = h("select", { "aria-label": "replay speed" }, [0.5, 1, 2, 4].map((s) => h("option", { value: s, selected: s === 1 }, `${s}×`)));
  const play = h("button", { class: "small" }, "Play");
  let position = 0;
  let playing = false;
  let last = null;

  const show = (time) => {
    position = Math.min(Math.max(time, 0), duration);
    let lo = 0;
    let hi = frames.length - 1;
    while (lo < hi) { const mid = (lo + hi + 1) >> 1; if (frames[mid].t <= position) lo = mid; else hi = mid - 1; }
    view.draw(frames[lo].poses);
    slider.value = String(Math.round((1000 * position) / duration));
    clock.textContent = `${position.toFixed(1)} / ${duration.toFixed(1)} s`;
  };
  const tick = (now) => {
    if (!playing || !view.element.isConnected) { playing = false; play.textContent = "Play"; return; }
    if (last !== null) show(position + ((now - last) / 1000) * Number(speed.value));
    last = now;
    if (position >= duration) { playing = false; play.textContent = "Replay"; return; }
    requestAnimationFrame(tick);
  };
  play.addEventListener("click", () => {
    if (playing) { playing = false; play.textContent = "Play"; return; }
    if (position >= duration) show(0);
    playing = true;
    last = null;
    play.textContent = "Pause";
    requestAnimationFrame(tick);
  });
  slider.addEventListener("input", () => { playing = false; play.textContent = "Play"; show((Number(slider.value) / 1000) * duration); });
  show(0);
  const source = data.source === "recording"
    ? "Recorded object poses from the simulation."
    : "No recording of this execution (trace robot): the trace is replayed step by step.";
  return h("div", { class: "replay", "data-source": data.source }, view.element,
    h("div", { class: "row controls" }, play, slider, speed, clock),
    h("p", { class: "muted small" }, source, " Objects: ", (data.objects ?? []).map(pretty).join(", ") || "none"));
}
