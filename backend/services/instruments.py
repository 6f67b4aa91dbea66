"""Standard HRI questionnaires, ready to add to a study's questionnaire, with their published wording, their
scoring rules and their citations: the System Usability Scale, NASA-TLX (raw), the Godspeed series and the
trust-in-automation scale of Jian et al. (2000). scores() turns a participant's answers into the scale scores."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from .plain_words import shown

# Answer scales beyond the study's own item kinds: (lowest, highest, step); the page labels only the two ends.
INSTRUMENT_KINDS: dict[str, tuple[int, int, int]] = {
    "anchored5": (1, 5, 1),  # five points, labelled at the ends (SUS, Godspeed)
    "anchored7": (1, 7, 1),  # seven points, labelled at the ends (Jian et al.)
    "tlx21": (0, 100, 5),  # NASA-TLX: 21 marks from 0 to 100 in steps of 5
}


@dataclass(frozen=True)
class Instrument:
    """A published questionnaire: its items [(key, text, (low anchor, high anchor))], answer kind and citation."""

    name: str
    title: str
    kind: str
    items: tuple[tuple[str, str, tuple[str, str]], ...]
    scoring: str
    citation: str


AGREE = ("Strongly disagree", "Strongly agree")
TLX = ("Very low", "Very high")
JIAN = ("Not at all", "Extremely")
GODSPEED_PROMPT = "Please rate your impression of the robot on this scale."

INSTRUMENTS: dict[str, Instrument] = {i.name: i for i in (
    Instrument(
        "sus", "System Usability Scale", "anchored5",
        tuple((f"sus{n}", text, AGREE) for n, text in enumerate((
            "I think that I would like to use this system frequently.",
            "I found the system unnecessarily complex.",
            "I thought the system was easy to use.",
            "I think that I would need the support of a technical person to be able to use this system.",
            "I found the various functions in this system were well integrated.",
            "I thought there was too much inconsistency in this system.",
            "I would imagine that most people would learn to use this system very quickly.",
            "I found the system very cumbersome to use.",
            "I felt very confident using the system.",
            "I needed to learn a lot of things before I could get going with this system.",
        ), start=1)),
        "sus: odd items score (answer - 1), even items (5 - answer); the sum times 2.5 (0-100). Every item answered.",
        "Brooke, J. (1996). SUS: A 'quick and dirty' usability scale. In P. W. Jordan, B. Thomas, B. A. Weerdmeester "
        "& I. L. McClelland (Eds.), Usability Evaluation in Industry (pp. 189-194). Taylor & Francis."),
    Instrument(
        "tlx", "NASA Task Load Index (raw)", "tlx21",
        (("tlx_mental", "Mental Demand: How mentally demanding was the task?", TLX),
         ("tlx_physical", "Physical Demand: How physically demanding was the task?", TLX),
         ("tlx_temporal", "Temporal Demand: How hurried or rushed was the pace of the task?", TLX),
         ("tlx_performance", "Performance: How successful were you in accomplishing what you were asked to do?",
          ("Perfect", "Failure")),
         ("tlx_effort", "Effort: How hard did you have to work to accomplish your level of performance?", TLX),
         ("tlx_frustration", "Frustration: How insecure, discouraged, irritated, stressed, and annoyed were you?",
          TLX)),
        "raw_tlx: the mean of the six ratings (0-100, no pairwise weighting), and each subscale's rating.",
        "Hart, S. G., & Staveland, L. E. (1988). Development of NASA-TLX (Task Load Index): Results of empirical and "
        "theoretical research. Advances in Psychology, 52, 139-183. Raw TLX: Hart, S. G. (2006). NASA-Task Load Index "
        "(NASA-TLX); 20 years later. Proceedings of the HFES Annual Meeting, 50(9), 904-908."),
    Instrument(
        "godspeed", "Godspeed questionnaire series", "anchored5",
        tuple((key, GODSPEED_PROMPT, anchors) for key, anchors in (
            ("anthropomorphism1", ("Fake", "Natural")), ("anthropomorphism2", ("Machinelike", "Humanlike")),
            ("anthropomorphism3", ("Unconscious", "Conscious")), ("anthropomorphism4", ("Artificial", "Lifelike")),
            ("anthropomorphism5", ("Moving rigidly", "Moving elegantly")),
            ("animacy1", ("Dead", "Alive")), ("animacy2", ("Stagnant", "Lively")),
            ("animacy3", ("Mechanical", "Organic")), ("animacy4", ("Artificial", "Lifelike")),
            ("animacy5", ("Inert", "Interactive")), ("animacy6", ("Apathetic", "Responsive")),
            ("likeability1", ("Dislike", "Like")), ("likeability2", ("Unfriendly", "Friendly")),
            ("likeability3", ("Unkind", "Kind")), ("likeability4", ("Unpleasant", "Pleasant")),
            ("likeability5", ("Awful", "Nice")),
            ("intelligence1", ("Incompetent", "Competent")), ("intelligence2", ("Ignorant", "Knowledgeable")),
            ("intelligence3", ("Irresponsible", "Responsible")), ("intelligence4", ("Unintelligent", "Intelligent")),
            ("intelligence5", ("Foolish", "Sensible")),
            ("safety1", ("Anxious", "Relaxed")), ("safety2", ("Agitated", "Calm")),
            ("safety3", ("Quiescent", "Surprised")))),
        "anthropomorphism, animacy, likeability, intelligence, safety: the mean of each series' items (1-5) as "
        "worded in the paper (no item reversed). Every item of a series answered.",
        "Bartneck, C., Kulic, D., Croft, E., & Zoghbi, S. (2009). Measurement instruments for the anthropomorphism, "
        "animacy, likeability, perceived intelligence, and perceived safety of robots. International Journal of "
        "Social Robotics, 1(1), 71-81."),
    Instrument(
        "trust", "Trust between people and automation (Jian et al.)", "anchored7",
        tuple((f"trust{n}", text, JIAN) for n, text in enumerate((
            "The system is deceptive.",
            "The system behaves in an underhanded manner.",
            "I am suspicious of the system's intent, action, or outputs.",
            "I am wary of the system.",
            "The system's actions will have a harmful or injurious outcome.",
            "I am confident in the system.",
            "The system provides security.",
            "The system has integrity.",
            "The system is dependable.",
            "The system is reliable.",
            "I can trust the system.",
            "I am familiar with the system.",
        ), start=1)),
        "distrust: the mean of items 1-5; trust: the mean of items 6-12 (1-7), the two factors the paper found. "
        "Every item of a factor answered.",
        "Jian, J.-Y., Bisantz, A. M., & Drury, C. G. (2000). Foundations for an empirically determined scale of trust "
        "in automated systems. International Journal of Cognitive Ergonomics, 4(1), 53-71."),
)}

# Each instrument's scores: (scale, item keys, how the answers become the score).
_GODSPEED_SERIES = ("anthropomorphism", "animacy", "likeability", "intelligence", "safety")


def instrument_items(name: str, *, prefix: str = "") -> list[dict[str, Any]]:
    """The questionnaire items of one instrument, as a study's questionnaire takes them (KeyError if unknown)."""
    instrument = INSTRUMENTS[name]
    return [{"id": f"{prefix}{key}", "text": text, "kind": instrument.kind, "required": True,
             "anchors": list(anchors), "instrument": name, "instrument_item": key}
            for key, text, anchors in instrument.items]


def catalogue() -> list[dict[str, Any]]:
    """Every instrument with its items, scoring rule and citation (GET /api/v1/instruments)."""
    return [{"name": i.name, "title": i.title, "kind": i.kind, "scoring": i.scoring, "citation": i.citation,
             "items": instrument_items(i.name)} for i in INSTRUMENTS.values()]


def _mean(values: list[int]) -> float:
    return round(sum(values) / len(values), 3)


def scores(questionnaire: list[dict[str, Any]], answers: dict[str, Any]) -> list[tuple[str, str, float, int]]:
    """One participant's instrument scores: (instrument, scale, score, items answered), for each scale whose
    items were all answered (a scale with a missing answer has no score)."""
    by_instrument: dict[str, dict[str, int]] = {}
    for item in questionnaire:
        name, key = item.get("instrument"), item.get("instrument_item")
        value = answers.get(item["id"])
        if name in INSTRUMENTS and key and isinstance(value, int) and not isinstance(value, bool):
            by_instrument.setdefault(name, {})[key] = value
    out: list[tuple[str, str, float, int]] = []
    for name, got in by_instrument.items():
        for scale, keys, score in _scales(name):
            if all(k in got for k in keys):
                out.append((name, scale, score([got[k] for k in keys]), len(keys)))
    return out


def _scales(name: str) -> list[tuple[str, list[str], Any]]:
    keys = [key for key, _text, _anchors in INSTRUMENTS[name].items]
    if name == "sus":
        return [("sus", keys, lambda v: round(2.5 * sum((x - 1) if i % 2 == 0 else (5 - x) for i, x in enumerate(v)),
                                              3))]
    if name == "tlx":
        return [("raw_tlx", keys, _mean)] + [(k.removeprefix("tlx_"), [k], _mean) for k in keys]
    if name == "godspeed":
        return [(series, [k for k in keys if k.startswith(series)], _mean) for series in _GODSPEED_SERIES]
    return [("distrust", keys[:5], _mean), ("trust", keys[5:], _mean)]


def instrument_fields(item: dict[str, Any], at: str, problems: Any) -> dict[str, Any]:
    """The instrument fields of a questionnaire item (anchors, instrument, instrument_item), checked."""
    out: dict[str, Any] = {}
    anchors = item.get("anchors")
    if anchors is not None:
        if (not isinstance(anchors, list) or len(anchors) != 2
                or not all(isinstance(a, str) and 0 < len(a) <= 60 for a in anchors)):
            problems.add(f"{at}.anchors", "expected two labels (the low and the high end), each text of 1 to 60 "
                         f"characters, got {shown(anchors)}")
        else:
            out["anchors"] = list(anchors)
    elif item.get("kind") in INSTRUMENT_KINDS:
        problems.add(f"{at}.anchors", f"a {item.get('kind')} item needs its two end labels, e.g. "
                     "['Strongly disagree', 'Strongly agree']")
    name, key = item.get("instrument"), item.get("instrument_item")
    if not isinstance(name, (str, type(None))) or not isinstance(key, (str, type(None))):
        return out  # not text: the study model names the field
    if name is not None or key is not None:
        known = {k for k, _t, _a in INSTRUMENTS[name].items} if name in INSTRUMENTS else set()
        if name not in INSTRUMENTS:
            problems.add(f"{at}.instrument", f"is {name!r}; expected one of {', '.join(INSTRUMENTS)}")
        elif key not in known:
            problems.add(f"{at}.instrument_item", f"is {key!r}; expected an item of {name}: {', '.join(sorted(known))}")
        else:
            out.update(instrument=name, instrument_item=key)
    return out
