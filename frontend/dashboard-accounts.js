// Accounts on the dashboard: an owner's page of people and their API tokens (create with a role, set a password,
// issue a token with its expiry, revoke one, disable a person), and every person's own page (change the password).

import * as api from "./dashboard-api.js";
import { h } from "./dom.js";
import { field, pill, setCrumbs, showFieldErrors, toast, when } from "./dashboard-ui.js";

export const ROLES = [["experimenter", "studies and participants, not accounts"],
  ["analyst", "read and export only"], ["owner", "everything, accounts included"]];
const ROLE_WORDS = Object.fromEntries(ROLES);
const MAX_TOKEN_DAYS = 366; // services/accounts.py
const MIN_PASSWORD = 12;

const app = () => document.getElementById("app");

function tokenStatus(t) {
  if (t.revoked_at) return pill(`revoked ${when(t.revoked_at)}`, "neutral");
  if (Date.parse(t.expires_at) <= Date.now()) return pill("expired", "neutral");
  return pill("active", "good");
}

/** The owner's page: people, adding one, passwords, API tokens. */
export async function accountsView(me) {
  setCrumbs({ text: "Studies", href: "#/" }, { text: "Accounts" });
  if (me.role !== "owner") {
    app().replaceChildren(h("h1", {}, "Accounts"), h("p", { class: "card muted" },
      `Only an owner manages accounts; you are ${me.name} with the role ${me.role}. `,
      h("a", { href: "#/account" }, "Your own account"), " is where you change your password."));
    return;
  }
  const peopleBox = h("div", { id: "people-box" });
  const tokensBox = h("div", { id: "tokens-box" });
  const issued = h("div", { id: "issued-token" });
  const personSelects = [];
  const refresh = async () => {
    const [people, tokens] = await Promise.all([api.people(), api.allTokens()]);
    renderPeople(peopleBox, people, me, refresh);
    renderTokens(tokensBox, tokens, refresh);
    const enabled = people.filter((p) => !p.disabled_at);
    for (const select of personSelects) {
      const chosen = select.value;
      select.replaceChildren(h("option", { value: "" }, enabled.length ? "choose a person" : "nobody yet: add a person"),
        ...enabled.map((p) => h("option", { value: p.name, selected: p.name === chosen }, `${p.name} (${p.role})`)));
    }
  };
  const personSelect = (id) => {
    const select = h("select", { id, required: true });
    personSelects.push(select);
    return select;
  };
  app().replaceChildren(
    h("div", { class: "page-head" }, h("div", {}, h("h1", {}, "Accounts"),
      h("p", { class: "muted" }, "Each person logs in with their own name and password, or uses their own API token, ",
        "so the audit log says who did what. The server's experimenter key stays an owner."))),
    h("section", { class: "card" }, h("h2", {}, "People"), peopleBox),
    h("div", { class: "account-forms" }, addPersonForm(refresh), setPasswordForm(personSelect("password-person"), refresh)),
    h("section", { class: "card" }, h("h2", {}, "API tokens"),
      h("p", { class: "muted small" }, "For scripts (tableteach teach, export) and the dashboard's token login. ",
        "A token is shown once, when it is issued; the server keeps only its digest. Dashboard logins are tokens too ",
        "(12 hours): revoking one logs that session out."),
      issueTokenForm(personSelect("token-person"), issued, refresh), issued, tokensBox));
  await refresh();
}

function renderPeople(box, people, me, refresh) {
  if (!people.length) {
    box.replaceChildren(h("p", { class: "muted", id: "people-empty" }, "No accounts yet: everyone uses the server's key. "
      + "Add a person below."));
    return;
  }
  const disable = async (person) => {
    const self = person.name === me.name ? " That is you: you are logged out." : "";
    if (!confirm(`Disable the account ${person.name}? Every token of theirs and their dashboard logins stop working `
      + `at once; what they did stays in the audit log.${self}`)) return;
    try {
      await api.disablePerson(person.name);
      toast(`${person.name} is disabled`);
      await refresh();
    } catch (error) {
      toast(error.detail ?? String(error), "error");
    }
  };
  box.replaceChildren(h("div", { class: "table-scroll" }, h("table", { class: "data", id: "people" },
    h("thead", {}, h("tr", {}, ["Name", "Role", "Password", "Created", "Status", ""].map((c) => h("th", { scope: "col" }, c)))),
    h("tbody", {}, people.map((p) => h("tr", { "data-person": p.name },
      h("td", {}, p.name), h("td", { title: ROLE_WORDS[p.role] ?? "" }, p.role),
      h("td", {}, p.has_password ? "set" : h("span", { class: "muted" }, "none (token only)")),
      h("td", {}, when(p.created_at)),
      h("td", {}, p.disabled_at ? pill(`disabled ${when(p.disabled_at)}`, "neutral") : pill("active", "good")),
      h("td", {}, p.disabled_at ? null : h("button", { type: "button", class: "small erase", "data-disable": p.name,
        onclick: () => disable(p) }, "Disable…"))))))));
}

function addPersonForm(refresh) {
  const name = h("input", { type: "text", id: "new-person-name", required: true, maxlength: 64, autocomplete: "off" });
  const role = h("select", { id: "new-person-role" }, ROLES.map(([r, words]) => h("option", { value: r }, `${r}: ${words}`)));
  const password = h("input", { type: "password", id: "new-person-password", autocomplete: "new-password",
    minlength: MIN_PASSWORD, maxlength: 1000 });
  const status = h("div", { id: "add-person-message" });
  const form = h("form", { class: "card form", id: "add-person", onsubmit: async (event) => {
    event.preventDefault();
    try {
      const made = await api.addPerson(name.value.trim(), role.value, password.value);
      showFieldErrors(form, status, null);
      toast(`Account ${made.name} (${made.role}) created`);
      form.reset();
      await refresh();
    } catch (error) {
      showFieldErrors(form, status, error);
    }
  } },
  h("h2", {}, "Add a person"),
  field("Name (what they log in with and the audit log shows)", name, "name"),
  field("Role", role, "role"),
  field(`Password for the dashboard (optional, ${MIN_PASSWORD} characters or more; tell it to them privately)`,
    password, "password"),
  h("div", { class: "row" }, h("button", { type: "submit", class: "primary" }, "Add the person")), status);
  return form;
}

function setPasswordForm(person, refresh) {
  const password = h("input", { type: "password", id: "set-password-value", autocomplete: "new-password", required: true,
    minlength: MIN_PASSWORD, maxlength: 1000 });
  const status = h("div", { id: "set-password-message" });
  const form = h("form", { class: "card form", id: "set-password", onsubmit: async (event) => {
    event.preventDefault();
    try {
      const answer = await api.setPassword(person.value, password.value);
      showFieldErrors(form, status, null);
      toast(`New password set for ${answer.name}; ${answer.ended_logins} dashboard login(s) of theirs ended`);
      form.reset();
      await refresh();
    } catch (error) {
      showFieldErrors(form, status, error);
    }
  } },
  h("h2", {}, "Set a person's password"),
  h("p", { class: "muted small" }, "For a forgotten password or a first one. Their open dashboard logins end; their API "
    + "tokens stay."),
  field("Person", person, "name"), field(`New password (${MIN_PASSWORD} characters or more)`, password, "password"),
  h("div", { class: "row" }, h("button", { type: "submit" }, "Set the password")), status);
  return form;
}

function issueTokenForm(person, issued, refresh) {
  const label = h("input", { type: "text", id: "token-label", value: "api", maxlength: 100 });
  const days = h("input", { type: "number", id: "token-days", value: 90, min: 1, max: MAX_TOKEN_DAYS, step: 1, required: true });
  const status = h("div", { id: "issue-token-message" });
  const form = h("form", { class: "form", id: "issue-token", onsubmit: async (event) => {
    event.preventDefault();
    try {
      const answer = await api.issueToken(person.value, label.value.trim() || "api", Number(days.value));
      showFieldErrors(form, status, null);
      const value = h("input", { id: "new-token", readonly: true, value: answer.token, class: "grow",
        "aria-label": `the new token of ${answer.name}` });
      issued.replaceChildren(h("div", { class: "issued", role: "status" },
        h("p", {}, h("b", {}, `Token for ${answer.name}`), ` (${answer.label}), valid until ${when(answer.expires_at)}. `,
          "Copy it now: it is not shown again."),
        h("div", { class: "row" }, value, h("button", { type: "button", onclick: async () => {
          try { await navigator.clipboard.writeText(answer.token); } catch { value.select(); document.execCommand?.("copy"); }
          toast("Token copied");
        } }, "Copy"), h("button", { type: "button", class: "ghost", onclick: () => issued.replaceChildren() }, "Done"))));
      await refresh();
    } catch (error) {
      showFieldErrors(form, status, error);
    }
  } },
  h("div", { class: "row token-fields" }, field("Person", person, "name"), field("Label (what it is for)", label, "label"),
    field(`Valid for (days, at most ${MAX_TOKEN_DAYS})`, days, "days"),
    h("button", { type: "submit", class: "primary" }, "Issue a token")), status);
  return form;
}

function renderTokens(box, tokens, refresh) {
  if (!tokens.length) {
    box.replaceChildren(h("p", { class: "muted", id: "tokens-empty" }, "No tokens issued yet."));
    return;
  }
  const revoke = async (t) => {
    if (!confirm(`Revoke token #${t.id} of ${t.name} (${t.label})? It stops working at once.`)) return;
    try {
      await api.revokeToken(t.id);
      toast(`Token #${t.id} revoked`);
      await refresh();
    } catch (error) {
      toast(error.detail ?? String(error), "error");
    }
  };
  box.replaceChildren(h("div", { class: "table-scroll" }, h("table", { class: "data", id: "tokens" },
    h("thead", {}, h("tr", {}, ["#", "Person", "Label", "Issued", "Expires", "Status", ""].map((c) => h("th", { scope: "col" }, c)))),
    h("tbody", {}, tokens.map((t) => {
      const live = !t.revoked_at && Date.parse(t.expires_at) > Date.now();
      return h("tr", { "data-token": t.id }, h("td", { class: "num" }, t.id), h("td", {}, t.name), h("td", {}, t.label),
        h("td", {}, when(t.created_at)), h("td", {}, when(t.expires_at)), h("td", {}, tokenStatus(t)),
        h("td", {}, live ? h("button", { type: "button", class: "small", "data-revoke": t.id, onclick: () => revoke(t) },
          "Revoke…") : null));
    })))));
}

/** Every person's own page: who they are and a password change. */
export function accountView(me) {
  setCrumbs({ text: "Studies", href: "#/" }, { text: "Your account" });
  const facts = h("dl", { class: "card facts", id: "me-facts" }, h("dt", {}, "Name"), h("dd", {}, me.name),
    h("dt", {}, "Role"), h("dd", {}, `${me.role} (${ROLE_WORDS[me.role] ?? ""})`));
  if (me.server_key) {
    app().replaceChildren(h("h1", {}, "Your account"), facts, h("p", { class: "card muted", id: "server-key-note" },
      "You are logged in with the server's experimenter key. It has no account and no password: it is set in the ",
      "server's environment (TABLETEACH_EXPERIMENTER_TOKEN). To act under your own name, ",
      h("a", { href: "#/accounts" }, "add an account for yourself"), " and log in with it."));
    return;
  }
  const current = h("input", { type: "password", id: "current-password", autocomplete: "current-password", required: true });
  const next = h("input", { type: "password", id: "new-password", autocomplete: "new-password", required: true,
    minlength: MIN_PASSWORD, maxlength: 1000 });
  const again = h("input", { type: "password", id: "repeat-password", autocomplete: "new-password", required: true });
  const status = h("div", { id: "password-message" });
  const form = h("form", { class: "card form", id: "change-password", onsubmit: async (event) => {
    event.preventDefault();
    if (next.value !== again.value) {
      showFieldErrors(form, status, new api.ApiError(422, "the passwords differ",
        [{ field: "repeat_password", message: "is not the same as the new password" }]));
      return;
    }
    try {
      const answer = await api.changePassword(current.value, next.value);
      showFieldErrors(form, status, null);
      form.reset();
      status.replaceChildren(h("p", { class: "ok", role: "status" }, "Your password is changed. ",
        answer.ended_logins ? `${answer.ended_logins} other dashboard login(s) of yours ended; this one stays.`
          : "No other dashboard login of yours was open."));
    } catch (error) {
      showFieldErrors(form, status, error);
    }
  } },
  h("h2", {}, "Change your password"),
  h("input", { type: "text", name: "username", autocomplete: "username", value: me.name, hidden: true }),
  field("Current password", current, "current_password"),
  field(`New password (${MIN_PASSWORD} characters or more)`, next, "new_password"),
  field("New password again", again, "repeat_password"),
  h("div", { class: "row" }, h("button", { type: "submit", class: "primary" }, "Change the password")), status);
  app().replaceChildren(h("h1", {}, "Your account"), facts, form);
}
