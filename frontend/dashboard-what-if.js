// The dashboard's teacher-consistency flag and "what if" panel for one participant: their recorded
// demonstrations and verdicts replayed through other learners, beside the study's own (tableteach replay's view).
// Read only. All text from the server goes through textContent, never innerHTML.

import * as api from "./dashboard-api.js";
import { PALETTE, lineChart } from "./charts.js";
import { h } from "./dom.js";

const fixed = (v, digits = 3) => (v === null || v === undefined ? "–" : Number(v).toFixed(digits));
const percent = (p) => (p === null || p === undefined ? "–" : p < 0.001 ? "<0.1%" : `${(100 * p).toFixed(p < 0.1 ? 1 : 0)}%`);

// The learners offered with one click; any other spec can be typed (prior=NAME, flip=P, data=all|demonstrations).
const PRESETS = [
  ["flip=0.1", "noise-aware, flip 0.1"],
  ["flip=0.2", "noise-aware, flip 0.2"],
  ["data=demonstrations", "demonstrations only (Batch)"],
  ["flip=0", "authors' learner"],
  ["prior=chains-2020", "prior chains-2020"],
];

/** The live table's flag: a pill when one of the participant's verdicts was one the learner found nearly impossible. */
export function consistencyPill(p) {
  const c = p.consistency;
  if (!c || !c.flagged) return null;
  const tasks = c.tasks.filter((t) => t.flagged).map((t) => `task ${t.task_index + 1}: lowest ${percent(t.lowest)}`);
  return h("span", { class: "pill pill-flag", "data-consistency": "flagged",
    title: `A verdict had a probability below ${percent(c.flag_below)} just before it was given (${tasks.join("; ")}); `
      + `lowest task score ${fixed(c.score, 2)}. A reason to look at the session, not a verdict on the participant.` },
  "improbable verdict");
}

/** A task's consistency line for the participant's page. */
export function consistencyNote(task) {
  const c = task.consistency;
  if (!c || !c.n_verdicts) return h("p", { class: "muted small consistency" }, "Teacher consistency: no verdicts yet.");
  return h("p", { class: "small consistency", "data-flagged": String(c.flagged) },
    h("b", {}, "Teacher consistency "), `${fixed(c.score, 2)} `,
    h("span", { class: "muted" }, `(mean probability the learner gave the ${c.n_verdicts} verdicts just before each; `
      + `the least probable ${percent(c.lowest)})`),
    c.flagged ? h("span", { class: "pill pill-flag", title: `a verdict's probability was below ${percent(c.flag_below)}: `
      + "look at that step's replay and the demonstrations before it" }, "improbable verdict") : null);
}

function chart(task) {
  const series = task.learners.filter((l) => !l.unavailable).map((l, i) => ({
    name: l.learner === "study" ? "study's learner" : l.learner, color: PALETTE[i % PALETTE.length], dashed: l.learner !== "study",
    points: l.steps.map((s) => ({ x: s.step, y: task.has_ground_truth ? s.similarity : s.entropy,
      label: `${l.learner} after step ${s.step}: ${fixed(task.has_ground_truth ? s.similarity : s.entropy)}` })),
  }));
  return lineChart(series, task.has_ground_truth
    ? { title: "Similarity to the ground truth", xLabel: "learning step", yMin: 0, yMax: 1, width: 420, height: 220, integerX: true }
    : { title: "Belief entropy (nats)", xLabel: "learning step", yMin: 0, width: 420, height: 220, integerX: true });
}

function finals(task) {
  const study = task.learners[0].steps.at(-1);
  return h("table", { class: "data small what-if-finals" },
    h("thead", {}, h("tr", {}, ["Learner", "Prior", "Flip rate", "Data", "Final similarity", "vs study", "Entropy", "MAP formula"]
      .map((c) => h("th", {}, c)))),
    h("tbody", {}, task.learners.map((l) => {
      if (l.unavailable) {  // e.g. the noise-aware learner past five objects: said, not drawn
        return h("tr", { "data-learner": l.learner, "data-unavailable": "true" },
          h("td", {}, l.learner), h("td", {}, l.prior), h("td", { class: "num" }, fixed(l.flip_rate, 2)), h("td", {}, l.data),
          h("td", { colspan: 4, class: "muted" }, `Not available: ${l.unavailable}`));
      }
      const last = l.steps.at(-1);
      const diff = last.similarity === null ? null : last.similarity - study.similarity;
      return h("tr", { "data-learner": l.learner }, h("td", {}, l.learner === "study" ? "the study's" : l.learner),
        h("td", {}, l.prior), h("td", { class: "num" }, fixed(l.flip_rate, 2)), h("td", {}, l.data),
        h("td", { class: "num" }, fixed(last.similarity)), h("td", { class: "num" }, diff === null ? "–" : `${diff >= 0 ? "+" : ""}${diff.toFixed(3)}`),
        h("td", { class: "num" }, fixed(last.entropy, 2)), h("td", {}, h("code", { class: "formula" }, last.map_formula)));
    })));
}

/** The "what if" card: choose learners, replay this participant's data through them, compare with the study's. */
export function whatIfSection(studyId, participantId) {
  const results = h("div", { class: "what-if-results" });
  const custom = h("input", { name: "what_if_custom", id: "what-if-custom", placeholder: "e.g. prior=chains-2019,flip=0.05",
    "aria-label": "another learner" });
  const boxes = PRESETS.map(([spec, label], i) => h("label", { class: "inline" },
    h("input", { type: "checkbox", name: "what_if_learner", value: spec, checked: i === 0 || i === 2 }), label));
  const run = async () => {
    const learners = boxes.map((b) => b.querySelector("input")).filter((b) => b.checked).map((b) => b.value);
    if (custom.value.trim()) learners.push(custom.value.trim());
    results.replaceChildren(h("p", { class: "muted" }, "Replaying…"));
    try {
      const data = await api.whatIf(studyId, participantId, learners);
      results.replaceChildren(...(data.tasks.length ? data.tasks.map((task) => h("div", { class: "what-if-task", "data-task": task.task_index },
        h("h3", {}, task.name ?? `Task ${task.task_index + 1}`), h("div", { class: "chart-row" }, chart(task)), finals(task)))
        : [h("p", { class: "muted" }, "This participant has not started a task yet.")]));
    } catch (error) {
      results.replaceChildren(h("div", { class: "error", role: "alert" }, error.detail ?? String(error)));
    }
  };
  return h("section", { class: "card what-if", id: "what-if" },
    h("h2", {}, "What if: other learners on the same data"),
    h("p", { class: "small muted" }, "This participant's demonstrations and verdicts, replayed through other learners. "
      + "The robot's queries stay the ones it asked; only what is learned from them changes. Nothing the participant saw is changed."),
    h("div", { class: "row wrap" }, boxes, custom,
      h("button", { type: "button", id: "what-if-run", onclick: run }, "Compare")),
    results);
}
