"""A task's goal picture for a scene with its own objects: Table B from above as an SVG drawing, each object the task
places drawn in its slot in its colour and labelled, optional ones marked, forbidden ones listed under the table.

Drawn as the participant's 2D view shows the tables (the robot at the top, the participant at the bottom), so a
slot's x is to the right and its y upwards. Names are validated identifiers and colours #rrggbb, and every text
is escaped all the same.
"""

from __future__ import annotations

from xml.sax.saxutils import escape, quoteattr

from .geometry import TABLE_HALF, dimensions
from .spec import ObjectSpec, SceneSpec

PAD = 24  # drawing units (millimetres) around the table
TITLE = 44  # room above the table for the title
FONT = 17


def _label(name: str) -> str:
    return name.replace("_", " ")


def _shape(o: ObjectSpec, cx: float, cy: float) -> list[str]:
    """SVG elements of one object seen from above, centred at (cx, cy), in millimetres."""
    d = dimensions(o)
    r = o.size * 5  # half the size, cm -> mm
    fill = quoteattr(o.colour)
    line = 'stroke="#4a4a4a" stroke-width="1.5"'
    if o.shape == "plate":
        return [f'<circle cx="{cx:.1f}" cy="{cy:.1f}" r="{r:.1f}" fill={fill} {line}/>',
                f'<circle cx="{cx:.1f}" cy="{cy:.1f}" r="{0.75 * r:.1f}" fill="none" stroke="#ffffff" '
                'stroke-opacity="0.6" stroke-width="2"/>']
    if o.shape == "bowl":
        return [f'<circle cx="{cx:.1f}" cy="{cy:.1f}" r="{r:.1f}" fill={fill} {line}/>',
                f'<circle cx="{cx:.1f}" cy="{cy:.1f}" r="{0.6 * r:.1f}" fill="#000000" fill-opacity="0.18"/>']
    if o.shape == "cup":  # the handle points at the participant (the object's +x)
        return [f'<rect x="{cx - 4:.1f}" y="{cy + r - 2:.1f}" width="8" height="{d.half_x * 1000 - r + 2:.1f}" '
                f'rx="3" fill={fill} {line}/>',
                f'<circle cx="{cx:.1f}" cy="{cy:.1f}" r="{r:.1f}" fill={fill} {line}/>',
                f'<circle cx="{cx:.1f}" cy="{cy:.1f}" r="{r - 5:.1f}" fill="#000000" fill-opacity="0.25"/>']
    if o.shape == "glass":
        return [f'<circle cx="{cx:.1f}" cy="{cy:.1f}" r="{r:.1f}" fill={fill} fill-opacity="0.55" {line}/>',
                f'<circle cx="{cx:.1f}" cy="{cy:.1f}" r="{r - 4:.1f}" fill="none" stroke="#ffffff" '
                'stroke-width="1.5"/>']
    if o.shape == "utensil":  # lies towards the robot: head at the top, handle at the bottom
        head, handle = 0.55 * 2 * r, 0.45 * 2 * r
        return [f'<rect x="{cx - 9:.1f}" y="{cy - r:.1f}" width="18" height="{head:.1f}" rx="8" fill={fill} {line}/>',
                f'<rect x="{cx - 8:.1f}" y="{cy + r - handle:.1f}" width="16" height="{handle:.1f}" rx="5" '
                f'fill="#3b3b3b" {line}/>']
    return [f'<rect x="{cx - r:.1f}" y="{cy - r:.1f}" width="{2 * r:.1f}" height="{2 * r:.1f}" rx="6" '
            f'fill={fill} {line}/>',
            f'<rect x="{cx - r + 6:.1f}" y="{cy - r + 6:.1f}" width="{2 * r - 12:.1f}" height="{2 * r - 12:.1f}" '
            'rx="4" fill="none" stroke="#000000" stroke-opacity="0.25" stroke-width="2"/>']


Box = tuple[float, float, float, float]  # left, top, right, bottom


def _tag_width(text: str) -> float:
    return 0.58 * FONT * len(text) + 12


def _box(text: str, x: float, y: float) -> Box:
    width = _tag_width(text)
    return (x - width / 2, y - FONT * 0.75, x + width / 2, y + FONT * 0.75)


def _overlap(a: Box, b: Box, gap: float = 2.0) -> float:
    """The area two boxes (grown by gap) share."""
    w = min(a[2], b[2]) - max(a[0], b[0]) + gap
    h = min(a[3], b[3]) - max(a[1], b[1]) + gap
    return max(w, 0.0) * max(h, 0.0)


def place_labels(labels: list[tuple[str, float, float]], area: Box) -> list[tuple[float, float]]:
    """Where each label goes: on its object, or, where that would cover a label placed before it, the nearest spot
    above, below or beside it (inside area) that covers none (else the one covering least). Crowded tables (up to
    ten objects) stay legible; labels that fit stay centred on their objects."""
    step = FONT * 1.5 + 3
    placed: list[Box] = []
    out = []
    for text, x, y in labels:
        half = _tag_width(text) / 2 + 6
        offsets = [(0.0, k * step) for k in (0, -1, 1, -2, 2, -3, 3)]
        offsets += [(sx * half, k * step) for k in (0, -1, 1) for sx in (1, -1)]
        best: tuple[float, float, float] | None = None
        for dx, dy in offsets:
            box = _box(text, x + dx, y + dy)
            if box[0] < area[0] or box[2] > area[2] or box[1] < area[1] or box[3] > area[3]:
                continue
            covered = sum(_overlap(box, other) for other in placed)
            if best is None or covered < best[0]:
                best = (covered, x + dx, y + dy)
            if covered == 0:
                break
        bx, by = (x, y) if best is None else best[1:]
        placed.append(_box(text, bx, by))
        out.append((bx, by))
    return out


def _tag(text: str, x: float, y: float) -> list[str]:
    """A label with a white backing, centred at (x, y)."""
    width = _tag_width(text)
    return [f'<rect x="{x - width / 2:.1f}" y="{y - FONT * 0.75:.1f}" width="{width:.1f}" height="{FONT * 1.5:.1f}" '
            'rx="7" fill="#ffffff" fill-opacity="0.92" stroke="#333333" stroke-width="1"/>',
            f'<text x="{x:.1f}" y="{y + FONT * 0.35:.1f}" text-anchor="middle" font-size="{FONT}">'
            f"{escape(text)}</text>"]


def goal_svg(spec: SceneSpec, title: str, *, shown: frozenset[str] | None = None,
             optional: frozenset[str] = frozenset(), forbidden: frozenset[str] = frozenset()) -> str:
    """The goal picture: the `shown` objects (all when None) in their slots, `optional` ones marked, `forbidden` ones
    named under the table."""
    width_mm, depth_mm = 2 * TABLE_HALF[1] * 1000, 2 * TABLE_HALF[0] * 1000
    notes = 1 if forbidden else 0
    width, height = width_mm + 2 * PAD, depth_mm + 2 * PAD + TITLE + notes * 34
    cx, cy = PAD + width_mm / 2, TITLE + PAD + depth_mm / 2
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {width:.0f} {height:.0f}" role="img" '
             f'font-family="system-ui, sans-serif">',
             f"<title>{escape(title)}: Table B from above with the objects in their places</title>",
             f'<text x="{width / 2:.1f}" y="{TITLE * 0.62:.1f}" text-anchor="middle" font-size="20" '
             f'font-weight="bold">{escape(title)}</text>',
             f'<rect x="{PAD}" y="{TITLE + PAD}" width="{width_mm:.0f}" height="{depth_mm:.0f}" rx="14" '
             'fill="#8c6239"/>',
             f'<rect x="{PAD + 20}" y="{TITLE + PAD + 20}" width="{width_mm - 40:.0f}" height="{depth_mm - 40:.0f}" '
             'rx="6" fill="#eee6cc"/>',
             f'<text x="{cx:.1f}" y="{TITLE + PAD - 6:.1f}" text-anchor="middle" font-size="13" fill="#555555">'
             "the robot is on this side</text>"]
    drawn = [o for o in spec.objects if shown is None or o.name in shown]
    for o in drawn:
        parts += _shape(o, cx + o.slot.x * 10, cy - o.slot.y * 10)
    labels = [(_label(o.name) + (" (optional)" if o.name in optional else ""), cx + o.slot.x * 10,
               cy - o.slot.y * 10) for o in drawn]
    area = (PAD, TITLE + PAD, PAD + width_mm, TITLE + PAD + depth_mm)
    spots = place_labels(labels, area)
    for (_text, x, y), (lx, ly) in zip(labels, spots, strict=True):
        if (lx, ly) != (x, y):  # a label moved off its object points at it
            parts.append(f'<line x1="{x:.1f}" y1="{y:.1f}" x2="{lx:.1f}" y2="{ly:.1f}" stroke="#333333" '
                         'stroke-width="1.5"/>')
    for (text, _x, _y), (lx, ly) in zip(labels, spots, strict=True):
        parts += _tag(text, lx, ly)
    if forbidden:
        names = ", ".join(_label(o.name) for o in spec.objects if o.name in forbidden)
        parts.append(f'<text x="{width / 2:.1f}" y="{TITLE + 2 * PAD + depth_mm + 10:.1f}" text-anchor="middle" '
                     f'font-size="{FONT}">Never place: {escape(names)}</text>')
    parts.append("</svg>")
    return "\n".join(parts) + "\n"
