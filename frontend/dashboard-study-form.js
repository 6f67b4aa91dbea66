// The study form of the dashboard: a new study, or an edit of one (every field while it is a draft; only the
// fields that participants do not notice once it is open). Every field the server refuses is reported next to
// the field, all at once, in the server's words; a custom task's formula is shown in words as it is typed.

import * as api from "./dashboard-api.js";
import { h } from "./dom.js";

// What can change once participants can join (services/studies.py LIVE_FIELDS).
// One completion code per outcome (services/outcomes.py); the older single screened-out code is kept for old studies.
export const OUTCOME_CODES = [
  ["completion_code", "Completed"], ["declined_consent_code", "Declined consent"],
  ["failed_quiz_code", "Failed the quiz"], ["failed_attention_code", "Failed an attention check"],
  ["timed_out_code", "Timed out"], ["withdrew_code", "Withdrew (optional)"]];
const CODE_FIELDS = [...OUTCOME_CODES.map(([name]) => name), "screened_out_code"];
export const LIVE_FIELDS = ["name", "pilot", ...CODE_FIELDS, "completion_url", "timeout_minutes", "places"];
const TASK_HINT = "e.g. F(bowl) & (!fork U knife)";
// The consent page's structured sections (services/page_settings.py CONSENT_FORM_FIELDS): [name, label, rows].
const CONSENT_FORM = [
  ["researcher", "Researcher(s)", 1], ["institution", "Institution", 1], ["contact", "Contact (e-mail)", 1],
  ["ethics_approval", "Ethics approval (board and reference)", 1], ["duration", "Duration (empty: the page's estimate)", 1],
  ["payment", "Payment", 1], ["recorded", "What is recorded (empty: the default)", 2],
  ["retention", "Data retention", 2], ["withdrawal", "Right to withdraw (empty: the default)", 2],
];

function removeButton() {
  return h("button", { type: "button", class: "ghost", onclick: (e) => e.target.closest(".row, .block").remove() }, "Remove");
}

/** A field with its label and a slot for the server's message about it (data-field = the API's path). */
function field(label, input, path, { cls = "" } = {}) {
  input.dataset.field = path;
  return h("label", { class: `field ${cls}` }, label, input, h("span", { class: "field-error", "data-error-for": path }));
}

function optional(value) {
  const text = String(value ?? "").trim();
  return text === "" ? null : text;
}

/** "Add a standard questionnaire": SUS, NASA-TLX, Godspeed or trust, all its items at once (scored in scores.csv). */
function instrumentPicker(onAdd) {
  const choice = h("select", { id: "instrument", "aria-label": "Standard questionnaire" },
    h("option", { value: "" }, "Standard questionnaire…"));
  const cite = h("p", { class: "small muted", id: "instrument-citation" });
  let known = [];
  api.instruments().then((list) => {
    known = list;
    choice.append(...list.map((i) => h("option", { value: i.name }, `${i.title} (${i.items.length} items)`)));
  }).catch(() => { choice.disabled = true; });
  choice.addEventListener("change", () => {
    cite.textContent = known.find((i) => i.name === choice.value)?.citation ?? "";
  });
  const add = h("button", { type: "button", class: "ghost", id: "add-instrument", onclick: () => {
    const picked = known.find((i) => i.name === choice.value);
    if (picked) onAdd(picked.items);
  } }, "Add its items");
  return h("span", { class: "row" }, choice, add, cite);
}

export function studyFormView({ choices, study = null, onSaved }) {
  const d = study ?? choices.defaults;
  const editing = study !== null;
  const frozen = editing && study.status !== "draft";
  const select = (name, options, value) => h("select", { name, id: name },
    options.map((o) => h("option", { value: o, selected: o === value }, o)));
  const number = (name, label, min, max) => field(label,
    h("input", { type: "number", name, id: name, min, max, step: 1, value: d[name] ?? "" }), name);

  // ---- tasks
  const tasks = h("div", { class: "rows", id: "tasks" });
  const addTask = (task = { key: "task1" }) => {
    const i = tasks.children.length;
    const keySelect = select("task_key", choices.taskKeys, task.key);
    keySelect.setAttribute("aria-label", `Task ${i + 1}: which task`);
    const name = h("input", { name: "task_name", value: task.key === "custom" ? task.name ?? "" : "", placeholder: "Task name shown to participants" });
    const instructions = h("textarea", { name: "task_instructions", rows: 2, placeholder: "Instructions (empty: the formula in words)" });
    instructions.value = task.key === "custom" ? task.instructions ?? "" : "";
    const truth = h("input", { name: "ground_truth", value: task.key === "custom" ? task.ground_truth ?? "" : "", placeholder: TASK_HINT, class: "grow" });
    const words = h("p", { class: "formula-words small", "aria-live": "polite" });
    const custom = h("div", { class: "custom-task" },
      field("Name", name, `tasks.${i}.name`), field("Ground truth (LTL formula)", truth, `tasks.${i}.ground_truth`, { cls: "grow" }),
      words, field("Instructions", instructions, `tasks.${i}.instructions`, { cls: "wide" }));
    let timer = null;
    const describe = () => {
      clearTimeout(timer);
      const text = truth.value.trim();
      if (!text) { words.textContent = ""; return; }
      timer = setTimeout(async () => {
        try {
          const answer = await api.describeFormula(text, objectNames());
          words.className = "formula-words small ok";
          words.textContent = `In words: ${answer.description}`;
        } catch (error) {
          words.className = "formula-words small bad";
          words.textContent = error.detail?.replace(/^ground_truth: /, "") ?? String(error);
        }
      }, 250);
    };
    truth.addEventListener("input", describe);
    const showCustom = () => { custom.hidden = keySelect.value !== "custom"; };
    keySelect.addEventListener("change", showCustom);
    keySelect.dataset.field = `tasks.${i}.key`;
    tasks.append(h("div", { class: "block task-row" },
      h("div", { class: "row" }, h("span", { class: "muted" }, `Task ${i + 1}`), keySelect, removeButton()),
      h("span", { class: "field-error", "data-error-for": `tasks.${i}` }), custom));
    showCustom();
    describe();
  };
  (study?.tasks ?? [{ key: "task1" }]).forEach(addTask);

  // ---- the study's own objects (none: the paper's dinner table)
  const objects = h("div", { class: "rows", id: "objects" });
  const objectNames = () => [...objects.querySelectorAll("[name=object_name]")].map((i) => i.value.trim()).filter(Boolean);
  const addObject = (o = { name: "", shape: "plate", colour: "#3366cc", size: null, slot: { x: 0, y: 0 } }) => {
    const i = objects.children.length;
    const shape = select("object_shape", choices.shapes, o.shape);
    shape.removeAttribute("id"); // one per row: the label around it names it
    const size = h("input", { type: "number", name: "object_size", step: 0.5, value: o.size ?? "", size: 4 });
    const sizeHint = () => {
      const [low, high] = choices.sizes[shape.value] ?? [];
      size.min = low; size.max = high;
      size.placeholder = low === undefined ? "" : `${low}-${high}`;
    };
    shape.addEventListener("change", sizeHint);
    sizeHint();
    objects.append(h("div", { class: "row object-row" },
      field("Name", h("input", { name: "object_name", value: o.name, placeholder: "e.g. lunch_box", size: 12 }), `objects.${i}.name`),
      field("Shape", shape, `objects.${i}.shape`),
      field("Colour", h("input", { type: "color", name: "object_colour", value: o.colour }), `objects.${i}.colour`),
      field("Size (cm across or long)", size, `objects.${i}.size`),
      field("Place: cm right", h("input", { type: "number", name: "object_x", min: -24, max: 24, step: 0.5, value: o.slot.x, size: 4 }), `objects.${i}.slot`),
      field("cm towards the robot", h("input", { type: "number", name: "object_y", min: -22, max: 22, step: 0.5, value: o.slot.y, size: 4 }), `objects.${i}.slot.y`),
      removeButton()));
  };
  (study?.objects ?? []).forEach(addObject);
  objects.addEventListener("change", () => {
    for (const input of tasks.querySelectorAll("[name=ground_truth]")) input.dispatchEvent(new Event("input"));
  });

  // ---- comprehension quiz
  const quiz = h("div", { class: "rows", id: "quiz" });
  const addQuiz = (item = { id: "", text: "", options: ["", ""], correct: 0 }) => {
    const i = quiz.children.length;
    const options = h("textarea", { name: "quiz_options", rows: 2, placeholder: "one answer option per line" });
    options.value = item.options.join("\n");
    quiz.append(h("div", { class: "block quiz-row" },
      h("div", { class: "row" },
        field("Id", h("input", { name: "quiz_id", value: item.id, size: 10 }), `quiz.${i}.id`),
        field("Question", h("input", { name: "quiz_text", value: item.text }), `quiz.${i}.text`, { cls: "grow" }),
        removeButton()),
      h("div", { class: "row" },
        field("Options", options, `quiz.${i}.options`, { cls: "grow" }),
        field("Correct option (1 = first)", h("input", { type: "number", name: "quiz_correct", min: 1, max: 10,
          value: item.correct + 1 }), `quiz.${i}.correct`))));
  };
  (study?.quiz ?? []).forEach(addQuiz);

  // ---- questionnaire
  const items = h("div", { class: "rows", id: "items" });
  const addItem = (item = { id: "", text: "", kind: choices.itemKinds[0], required: true }) => {
    const i = items.children.length;
    const kind = select("item_kind", choices.itemKinds, item.kind);
    kind.setAttribute("aria-label", `Item ${i + 1}: answer scale`);
    const expected = h("input", { type: "number", name: "item_expected", min: 1, max: 5, value: item.expected ?? "", size: 3 });
    const expectedField = field("Expected answer (1-5)", expected, `questionnaire.${i}.expected`);
    const sync = () => { expectedField.hidden = kind.value !== "attention"; };
    kind.addEventListener("change", sync);
    kind.dataset.field = `questionnaire.${i}.kind`;
    // A standard questionnaire's item keeps its end labels and its place in the instrument (for scores.csv).
    const extra = Object.fromEntries(["anchors", "instrument", "instrument_item"].filter((k) => item[k] != null)
      .map((k) => [k, item[k]]));
    items.append(h("div", { class: "row item-row", "data-extra": JSON.stringify(extra),
      title: item.instrument ? `${item.instrument}: ${(item.anchors ?? []).join(" – ")}` : null },
      field("Id", h("input", { name: "item_id", value: item.id, placeholder: "e.g. learned", size: 12 }), `questionnaire.${i}.id`),
      field("Question", h("input", { name: "item_text", value: item.text, placeholder: "question text" }), `questionnaire.${i}.text`, { cls: "grow" }),
      kind, expectedField,
      h("label", { class: "inline" }, h("input", { type: "checkbox", name: "item_required", checked: item.required !== false }), "required"),
      removeButton()));
    sync();
  };
  (study?.questionnaire ?? []).forEach(addItem);

  const message = h("div", { id: "create-message" });
  const checkbox = (name, checked) => h("input", { type: "checkbox", name, id: name, checked: Boolean(checked) });

  const form = h("form", { class: "card form", id: "new-study-form", novalidate: true });
  const collect = () => {
    const f = new FormData(form);
    const int = (name) => (optional(f.get(name)) === null ? null : Number(f.get(name)));
    const own = [...objects.querySelectorAll(".object-row")].map((row) => {
      const value = (name) => row.querySelector(`[name=${name}]`).value;
      const number = (name) => (optional(value(name)) === null ? null : Number(value(name)));
      return { name: value("object_name").trim(), shape: value("object_shape"), colour: value("object_colour"),
        size: number("object_size"), slot: { x: number("object_x") ?? 0, y: number("object_y") ?? 0 } };
    });
    return {
      name: optional(f.get("name")) ?? (editing ? study.name : undefined),
      objects: own.length ? own : null,
      tasks: [...tasks.querySelectorAll(".task-row")].map((row) => {
        const key = row.querySelector("[name=task_key]").value;
        if (key !== "custom") return { key };
        return { key, name: optional(row.querySelector("[name=task_name]").value),
          instructions: optional(row.querySelector("[name=task_instructions]").value),
          ground_truth: optional(row.querySelector("[name=ground_truth]").value) };
      }),
      conditions: choices.conditions.filter((c) => f.get(`condition_${c}`)),
      assignment: f.get("assignment"), task_order: f.get("task_order"),
      n_practice: int("n_practice"), n_demonstrations: int("n_demonstrations"),
      n_queries: int("n_queries"), n_tests: int("n_tests"),
      prior: f.get("prior"), criterion: f.get("criterion"),
      quiz: [...quiz.querySelectorAll(".quiz-row")].map((row) => ({
        id: row.querySelector("[name=quiz_id]").value.trim(), text: row.querySelector("[name=quiz_text]").value.trim(),
        options: row.querySelector("[name=quiz_options]").value.split("\n").map((o) => o.trim()).filter(Boolean),
        correct: Number(row.querySelector("[name=quiz_correct]").value) - 1,
      })),
      quiz_max_attempts: int("quiz_max_attempts"),
      questionnaire: [...items.querySelectorAll(".item-row")].map((row) => {
        const item = { id: row.querySelector("[name=item_id]").value.trim(), text: row.querySelector("[name=item_text]").value,
          kind: row.querySelector("[name=item_kind]").value, required: row.querySelector("[name=item_required]").checked };
        if (item.kind === "attention") item.expected = Number(row.querySelector("[name=item_expected]").value) || null;
        return { ...item, ...JSON.parse(row.dataset.extra || "{}") };
      }),
      consent_text: optional(f.get("consent_text")), consent_version: optional(f.get("consent_version")),
      completion_url: optional(f.get("completion_url")),
      ...Object.fromEntries(CODE_FIELDS.map((name) => [name, optional(f.get(name))])),
      timeout_minutes: int("timeout_minutes"),
      places: int("places"),
      robot_speed: optional(f.get("robot_speed")) === null ? undefined : Number(f.get("robot_speed")),
      flip_rate: optional(f.get("flip_rate")) === null ? undefined : Number(f.get("flip_rate")),
      pilot: Boolean(f.get("pilot")),
      consent_form: Object.fromEntries(CONSENT_FORM.map(([name]) => [name, optional(f.get(`consent_${name}`))])),
      allow_anonymous: Boolean(f.get("allow_anonymous")), quiz_feedback: Boolean(f.get("quiz_feedback")),
    };
  };

  const showErrors = (error) => {
    for (const slot of form.querySelectorAll(".field-error")) slot.textContent = "";
    for (const input of form.querySelectorAll(".invalid")) input.classList.remove("invalid");
    const unplaced = [];
    for (const e of error.errors ?? []) {
      // The closest slot: tasks.0.ground_truth, else tasks.0, else the top of the form.
      const parts = e.field.split(".");
      let slot = null;
      for (let n = parts.length; n > 0 && !slot; n--) {
        slot = form.querySelector(`[data-error-for="${CSS.escape(parts.slice(0, n).join("."))}"]`);
      }
      if (slot) {
        slot.textContent = slot.textContent ? `${slot.textContent}; ${e.message}` : e.message;
        slot.previousElementSibling?.classList.add("invalid");
      } else unplaced.push(`${e.field}: ${e.message}`);
    }
    const count = error.errors?.length ?? 0;
    message.replaceChildren(h("div", { class: "error", role: "alert" },
      count ? `${count} field${count > 1 ? "s need" : " needs"} a change: see the messages in red above.` : error.detail,
      unplaced.length ? h("ul", {}, unplaced.map((u) => h("li", {}, u))) : null));
    form.querySelector(".invalid")?.focus();
  };

  form.addEventListener("submit", async (event) => {
    event.preventDefault();
    let spec = collect();
    if (frozen) spec = Object.fromEntries(LIVE_FIELDS.map((k) => [k, spec[k]]));
    message.replaceChildren(h("p", { class: "muted" }, editing ? "Saving…" : "Creating…"));
    try {
      const saved = editing ? await api.updateStudy(study.id, spec) : await api.createStudy(spec);
      onSaved(saved);
    } catch (error) {
      if (!(error instanceof api.ApiError)) throw error;
      showErrors(error);
    }
  });

  const section = (title, ...children) => h("fieldset", { "data-live": "no" }, h("legend", {}, title), ...children);
  form.append(...[
    h("h1", {}, editing ? `Edit ${study.name}` : "New study"),
    frozen ? h("p", { class: "note" }, `This study is ${study.status}: only its name, pilot flag, completion codes, `
      + "redirect and timeout can change. Clone it to change the rest.") : null,
    field("Name", h("input", { name: "name", id: "name", value: editing ? study.name : "", placeholder: choices.defaults.name }), "name", { cls: "grow" }),
    section("Objects (none: the paper's dinner table with its five objects)",
      h("p", { class: "small muted" }, "Each object's name is what the task formulas use (lower-case letters, digits "
        + "and _). Its place on Table B is measured from the table's centre as the goal picture shows it: to the right, "
        + "and towards the robot. The objects start on Table A, laid out by the server. A study takes 2 to 5 objects."),
      objects,
      h("span", { class: "field-error", "data-error-for": "objects" }),
      h("div", { class: "row" },
        h("button", { type: "button", class: "ghost", id: "add-object", onclick: () => addObject() }, "Add an object"),
        study?.objects ? h("a", { href: `/study/${encodeURIComponent(study.id)}/goal/0.svg`, target: "_blank",
          rel: "noopener", id: "goal-preview" }, "See the first task's goal picture") : null)),
    section("Tasks", tasks,
      h("button", { type: "button", class: "ghost", id: "add-task", onclick: () => addTask({ key: "task2" }) }, "Add a task"),
      field("Task order", select("task_order", choices.taskOrders, d.task_order ?? "fixed"), "task_order")),
    section("Conditions (protocols) and assignment",
      h("div", { class: "row" }, choices.conditions.map((c) => h("label", { class: "inline" },
        checkbox(`condition_${c}`, d.conditions.includes(c)), c)),
      field("Assignment", select("assignment", choices.assignments, d.assignment), "assignment")),
      h("span", { class: "field-error", "data-error-for": "conditions" })),
    section("Counts per task",
      h("div", { class: "row" }, number("n_practice", "Practice (first task only)", 0, 20),
        number("n_demonstrations", "Demonstrations", 0, 20), number("n_queries", "Queries", 0, 20),
        number("n_tests", "Tests", 0, 20))),
    section("Learner and robot",
      h("div", { class: "row" }, field("Prior", select("prior", choices.priors, d.prior), "prior"),
        field("Planning criterion", select("criterion", choices.criteria, d.criterion), "criterion"),
        field("Robot motion shown faster (1-3x; recordings keep real time)", h("input", { type: "number",
          name: "robot_speed", id: "robot_speed", min: 1, max: 3, step: 0.25, value: d.robot_speed ?? 1 }), "robot_speed"),
        field("Verdicts assumed wrong with probability (0: the authors' learner; below 0.5)", h("input", { type: "number",
          name: "flip_rate", id: "flip_rate", min: 0, max: 0.49, step: 0.01, value: d.flip_rate ?? 0 }), "flip_rate"))),
    section("Comprehension quiz (after the instructions)", quiz,
      h("div", { class: "row" },
        h("button", { type: "button", class: "ghost", id: "add-quiz", onclick: () => addQuiz() }, "Add a question"),
        number("quiz_max_attempts", "Attempts before screening out", 1, 10)),
      h("label", { class: "inline" }, checkbox("quiz_feedback", d.quiz_feedback ?? true),
        "After a failed attempt, say which answers were wrong")),
    section("Questionnaire (an attention check is shown as an agreement item)", items,
      h("div", { class: "row" },
        h("button", { type: "button", class: "ghost", id: "add-item", onclick: () => addItem() }, "Add an item"),
        instrumentPicker((list) => list.forEach(addItem)))),
    section("Consent",
      field("Consent text (empty: the default text, which explains withdrawal)", h("textarea", { name: "consent_text", rows: 3 }), "consent_text", { cls: "wide" }),
      field("Consent version", h("input", { name: "consent_version", value: editing ? study.consent_version : "", placeholder: "1" }), "consent_version"),
      h("div", { class: "row wrap" }, CONSENT_FORM.map(([name, label, rows]) => field(label, rows > 1
        ? h("textarea", { name: `consent_${name}`, rows })
        : h("input", { name: `consent_${name}`, value: study?.consent_form?.[name] ?? "" }), `consent_form.${name}`,
      { cls: rows > 1 ? "wide" : "" }))),
      h("label", { class: "inline" }, checkbox("allow_anonymous", d.allow_anonymous),
        "A link without PROLIFIC_PID may take part without an id (otherwise the page asks for the Prolific ID)")),
    h("fieldset", { "data-live": "yes" }, h("legend", {}, "Completion on Prolific"),
      field("Completion redirect ({code} is replaced)", h("input", { name: "completion_url", id: "completion_url",
        value: study?.completion_url ?? "", placeholder: "https://app.prolific.com/submissions/complete?cc={code}" }), "completion_url", { cls: "wide" }),
      h("p", { class: "small muted" }, "One code per outcome, each from Prolific's list of completion codes (empty: no code for it)."),
      h("div", { class: "row codes" },
        OUTCOME_CODES.map(([name, label]) => field(label, h("input", { name, id: name, value: study?.[name] ?? "" }), name)),
        study?.screened_out_code ? field("Screened-out code (older studies: for outcomes without their own code)",
          h("input", { name: "screened_out_code", id: "screened_out_code", value: study.screened_out_code }), "screened_out_code") : null),
      h("div", { class: "row" },
        field(editing && study.status !== "draft" ? "Time-out after (minutes idle, empty: never; a change counts idleness from the change)" : "Time-out after (minutes idle, empty: never)", h("input", { type: "number", name: "timeout_minutes", id: "timeout_minutes", min: 1, max: 1440, value: study?.timeout_minutes ?? "" }), "timeout_minutes"),
        field("Places (participants; empty: no limit)", h("input", { type: "number", name: "places", id: "places", min: 1, max: 100000, value: study?.places ?? "" }), "places")),
      h("label", { class: "inline" }, checkbox("pilot", d.pilot), "Pilot: participants who join now are flagged as pilots")),
    h("div", { class: "row" }, h("button", { type: "submit", class: "primary", id: "create" }, editing ? "Save changes" : "Create study"),
      h("a", { href: editing ? `#/study/${encodeURIComponent(study.id)}` : "#/", class: "button ghost" }, "Cancel")),
    message].filter(Boolean));
  if (editing) form.querySelector("[name=consent_text]").value = study.consent_text;
  for (const [name, , rows] of CONSENT_FORM) {
    if (rows > 1) form.querySelector(`[name=consent_${name}]`).value = study?.consent_form?.[name] ?? "";
  }
  if (frozen) {
    for (const set of form.querySelectorAll("fieldset[data-live=no]")) set.disabled = true;
  }
  return form;
}
