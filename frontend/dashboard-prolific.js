// A study's Prolific screen: upload Prolific's submissions export, compare its status with ours per Prolific id
// (mismatches flagged), set the bonus rule (an amount per outcome) and download the bulk-bonus file.

import * as api from "./dashboard-api.js";
import { h } from "./dom.js";
import { errorBox, field, pill, saveBlob, setCrumbs, showFieldErrors, toast, when } from "./dashboard-ui.js";

// The outcomes a participant's code says (services/outcomes.py), in the order a study runs.
const OUTCOMES = [["completed", "Completed"], ["declined_consent", "Declined consent"],
  ["comprehension", "Failed the quiz"], ["attention", "Failed an attention check"], ["timeout", "Timed out"],
  ["withdrew", "Withdrew"]];
const OUTCOME_WORDS = Object.fromEntries(OUTCOMES.map(([key, label]) => [key, label.toLowerCase()]));

export async function prolificView(studyId) {
  const [study, rule] = await Promise.all([api.getStudy(studyId), api.bonusRule(studyId)]);
  const studyHref = `#/study/${encodeURIComponent(studyId)}`;
  setCrumbs({ text: "Studies", href: "#/" }, { text: study.name, href: studyHref }, { text: "Prolific" });
  const tableBox = h("div", { id: "reconciliation-box" }, h("p", { class: "muted" }, "Loading…"));
  const bonusBox = h("div", { id: "bonus-preview" });
  const refreshTable = async () => {
    try {
      renderReconciliation(tableBox, await api.reconciliation(studyId), studyHref);
    } catch (error) {
      tableBox.replaceChildren(errorBox(error));
    }
  };
  const refreshBonuses = async () => {
    try {
      renderBonusFile(bonusBox, await api.bonusFile(studyId));
    } catch (error) {
      bonusBox.replaceChildren(error instanceof api.ApiError && error.status === 422
        ? h("p", { class: "muted" }, "No bonus rule yet: give an amount for at least one outcome and save.")
        : errorBox(error));
    }
  };
  app().replaceChildren(
    h("div", { class: "page-head" }, h("div", {}, h("h1", {}, "Prolific: reconcile and pay bonuses"),
      h("p", { class: "muted" }, study.name, " · ", h("code", {}, study.id))),
    h("a", { class: "button", href: studyHref }, "Back to the study")),
    uploadSection(studyId, refreshTable),
    h("section", { class: "card" }, h("h2", {}, "Prolific's status against ours"),
      h("p", { class: "muted small" }, "One row per Prolific id, from the uploaded export and this study's participants. ",
        "A mismatch says why the two disagree: a submission returned on Prolific but finished here, approved there but ",
        "screened out here, an id that never joined here or is missing on Prolific, a different code."),
      tableBox),
    bonusSection(studyId, rule, refreshBonuses, bonusBox));
  await Promise.all([refreshTable(), refreshBonuses()]);
}

const app = () => document.getElementById("app");

function uploadSection(studyId, refresh) {
  const file = h("input", { type: "file", id: "submissions-file", accept: ".csv,text/csv", required: true });
  const status = h("div", { id: "upload-message" });
  const form = h("form", { class: "form", id: "upload-form", onsubmit: async (event) => {
    event.preventDefault();
    const chosen = file.files[0];
    if (!chosen) return;
    status.replaceChildren(h("p", { class: "muted" }, "Uploading…"));
    try {
      const answer = await api.uploadSubmissions(studyId, await chosen.text());
      status.replaceChildren(h("p", { class: "muted" }, `${answer.n_submissions} submission(s) from ${chosen.name} `
        + `uploaded ${when(answer.uploaded_at)}.`));
      toast(`${answer.n_submissions} submission(s) uploaded`);
      form.reset();
      await refresh();
    } catch (error) {
      showFieldErrors(form, status, error);
      if (error instanceof api.ApiError && error.errors) {
        status.prepend(h("p", { class: "small" }, `${chosen.name} was not stored (an earlier upload is kept). `
          + "Fix these cells, or download the export from Prolific again:"));
      }
    }
  } },
  h("label", { for: "submissions-file" }, "Prolific's submissions export (CSV)"), file,
  h("div", { class: "row" }, h("button", { type: "submit", class: "primary" }, "Upload")), status);
  return h("section", { class: "card", id: "upload" }, h("h2", {}, "Upload the submissions"),
    h("p", { class: "muted small" }, "On Prolific: the study's Submissions page, then Download export. A new upload ",
      "replaces the earlier one. Read are the columns Participant id and Status, and if present Submission id and ",
      "Completion code."),
    form);
}

function ours(row) {
  if (row.participant_id === null) return h("span", { class: "muted" }, "never joined");
  if (row.outcome) return OUTCOME_WORDS[row.outcome] ?? row.outcome;
  return `under way (${(row.stage ?? "").replace("_", " ")})`;
}

function renderReconciliation(box, table, studyHref) {
  const rows = table.rows;
  if (!rows.length) {
    box.replaceChildren(h("p", { class: "muted", id: "reconciliation-empty" }, table.uploaded_at
      ? "The upload has no submissions and no participant came with a Prolific id."
      : "Nothing to compare yet: upload Prolific's export above (participants who came with a Prolific id are "
        + "listed here as they join)."));
    return;
  }
  const onlyMismatches = h("input", { type: "checkbox", id: "mismatches-only" });
  const body = h("tbody", {}, rows.map((r) => h("tr", { class: r.mismatch ? "mismatch" : "", "data-pid": r.prolific_pid },
    h("td", {}, h("code", {}, r.prolific_pid)),
    h("td", {}, r.prolific_status ?? h("span", { class: "muted" }, "not in the export")),
    h("td", {}, r.entered_code ? h("code", {}, r.entered_code) : h("span", { class: "muted" }, "–")),
    h("td", {}, r.participant_id === null ? h("span", { class: "muted" }, "–")
      : h("a", { href: `${studyHref}/p/${r.participant_id}` }, `#${r.participant_id}`)),
    h("td", {}, ours(r)),
    h("td", {}, r.completion_code ? h("code", {}, r.completion_code) : h("span", { class: "muted" }, "–")),
    h("td", { class: "mismatch-cell" }, r.mismatch ? [pill("mismatch", "bad"), " ", r.mismatch] : pill("agrees", "good")))));
  onlyMismatches.addEventListener("change", () => {
    for (const tr of body.children) tr.hidden = onlyMismatches.checked && !tr.classList.contains("mismatch");
  });
  box.replaceChildren(
    h("div", { class: "row small reconciliation-head" },
      h("span", { id: "reconciliation-summary" }, `${rows.length} Prolific id(s), `,
        h("b", {}, `${table.n_mismatches} mismatch(es)`),
        table.uploaded_at ? ` · export uploaded ${when(table.uploaded_at)}` : " · no export uploaded yet"),
      h("span", { class: "spacer" }),
      h("label", { class: "inline" }, onlyMismatches, "mismatches only")),
    h("div", { class: "table-scroll" }, h("table", { class: "data", id: "reconciliation" },
      h("thead", {}, h("tr", {}, ["Prolific id", "Status on Prolific", "Code entered", "Participant", "Here",
        "Code shown", "Mismatch"].map((c) => h("th", { scope: "col" }, c)))),
      body)));
}

function bonusSection(studyId, rule, refresh, preview) {
  const inputs = OUTCOMES.map(([key, label]) => {
    const input = h("input", { type: "number", id: `bonus-${key}`, min: 0, max: 100, step: 0.01, inputmode: "decimal",
      placeholder: "no bonus", value: rule.amounts[key] ?? "" });
    return [key, field(label, input, `amounts.${key}`), input];
  });
  const status = h("div", { id: "bonus-message" });
  const form = h("form", { class: "form", id: "bonus-form", onsubmit: async (event) => {
    event.preventDefault();
    const amounts = Object.fromEntries(inputs.filter(([, , input]) => input.value.trim() !== "")
      .map(([key, , input]) => [key, Number(input.value)]));
    try {
      const saved = await api.setBonusRule(studyId, amounts);
      for (const [key, , input] of inputs) input.value = saved.amounts[key] ?? "";
      showFieldErrors(form, status, null);
      toast("Bonus rule saved");
      await refresh();
    } catch (error) {
      showFieldErrors(form, status, error);
    }
  } },
  h("fieldset", {}, h("legend", {}, "Bonus per outcome"), h("div", { class: "bonus-grid" }, inputs.map(([, label]) => label))),
  h("div", { class: "row" }, h("button", { type: "submit", class: "primary" }, "Save the rule")), status);
  return h("section", { class: "card", id: "bonuses" }, h("h2", {}, "Bonuses"),
    h("p", { class: "muted small" }, "An amount per outcome, in the study's currency on Prolific (e.g. 1.50, at most ",
      "100). Each participant who came with a Prolific id gets the amount of their outcome; pilot participants and ",
      "outcomes left empty get none. On Prolific: Submissions, then Bulk bonus payments; paste the file's lines."),
    form, preview);
}

function renderBonusFile(box, file) {
  const lines = file.text.split("\n").filter(Boolean).map((line) => line.split(","));
  const cents = lines.reduce((sum, [, amount]) => sum + Math.round(100 * Number(amount)), 0);
  box.replaceChildren(
    h("div", { class: "row" }, h("p", { id: "bonus-summary" }, `${lines.length} bonus(es), `,
      h("b", {}, `${(cents / 100).toFixed(2)} in all`), lines.length ? "" : " (nobody's outcome is paid by the rule yet)"),
    h("span", { class: "spacer" }),
    h("button", { type: "button", id: "download-bonuses", disabled: !lines.length, onclick: () => saveBlob(file.filename, file.blob) },
      `Download ${file.filename}`)),
    lines.length ? h("div", { class: "table-scroll bonus-lines" }, h("table", { class: "data small", id: "bonus-lines" },
      h("thead", {}, h("tr", {}, h("th", { scope: "col" }, "Prolific id"), h("th", { scope: "col", class: "num" }, "Amount"))),
      h("tbody", {}, lines.map(([pid, amount]) => h("tr", {}, h("td", {}, h("code", {}, pid)), h("td", { class: "num" }, amount))))))
      : null);
}
