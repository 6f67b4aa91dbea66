"""A MuJoCo scene generated from a study's own objects (tableteach.scenes): the dinner scene's tables, lights, camera
and arm, with the dinner objects replaced by the specified ones, each on its start pose on Table A, with its slot on
Table B, its grasp site and its inactive grasp weld, following the conventions at the top of
sim_assets/dinner_table/scene.xml. The objects' names are listed in the custom text "tableteach_objects".

The text is a function of the specification only (same spec, same bytes), and a generated scene is stored under
the digest of its text (scene_path), so every process and host that generates it uses the same file name.
"""

from __future__ import annotations

import hashlib
import math
import os
import xml.etree.ElementTree as ET
from pathlib import Path

from ..scenes.geometry import TABLE_B, TABLE_TOP, dimensions, slot_pose
from ..scenes.layout import start_poses
from ..scenes.spec import ObjectSpec, SceneSpec
from .scene import OBJECTS_TEXT, SCENE_XML

DINNER_OBJECTS = ("dinner_plate", "small_plate", "bowl", "knife", "fork")
SCENE_FOLDER = "scenes"  # under the robot's cache folder (tableteach.sim.clips.CACHE_FOLDER)


def _num(value: float) -> str:
    text = f"{value:.5f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def _vec(*values: float) -> str:
    return " ".join(_num(v) for v in values)


def _rgba(colour: str, alpha: float = 1.0) -> str:
    rgb = [int(colour[i : i + 2], 16) / 255 for i in (1, 3, 5)]
    return _vec(*rgb, alpha)


def _shade(colour: str, factor: float) -> str:
    """The colour darkened (factor < 1) or lightened towards white (factor > 1), as #rrggbb."""
    rgb = [int(colour[i : i + 2], 16) for i in (1, 3, 5)]
    out = [min(255, round(c * factor)) if factor <= 1 else round(c + (255 - c) * (factor - 1)) for c in rgb]
    return "#" + "".join(f"{c:02x}" for c in out)


def _geom(body: ET.Element, **attrs: str) -> None:
    ET.SubElement(body, "geom", attrs)


def _object_body(o: ObjectSpec, x: float, y: float, yaw: float) -> ET.Element:
    """The object's body: geoms by shape (origin at the bottom centre), its free joint and its grasp site."""
    d = dimensions(o)
    body = ET.Element("body", {"name": o.name, "pos": _vec(x, y, TABLE_TOP)})
    if yaw:
        body.set("euler", _vec(0, 0, yaw))
    ET.SubElement(body, "freejoint", {"name": o.name})
    s = o.size / 100.0
    r = s / 2
    colour = _rgba(o.colour)
    if o.shape == "plate":
        _geom(body, name=o.name, type="cylinder", pos=_vec(0, 0, 0.006), size=_vec(r, 0.006),
              mass=_num(0.35 * (r / 0.1) ** 2), rgba=colour)
        _geom(body, **{"class": "decor"}, type="cylinder", pos=_vec(0, 0, 0.0125), size=_vec(0.75 * r, 0.0006),
              rgba=_rgba(_shade(o.colour, 1.35)))
    elif o.shape == "bowl":
        k = s / 0.135
        ET.SubElement(body, "inertial", {"pos": _vec(0, 0, 0.025 * k), "mass": _num(0.25 * k * k),
                                         "diaginertia": _vec(0.0004 * k * k, 0.0004 * k * k, 0.0005 * k * k)})
        _geom(body, name=o.name, type="cylinder", pos=_vec(0, 0, 0.004), size=_vec(0.04 * k, 0.004), rgba=colour)
        for i in range(12):  # the wall: a ring of tilted boards, drawn and colliding (a concave hull)
            a = 2 * math.pi * i / 12
            _geom(body, type="box", pos=_vec(0.057 * k * math.cos(a), 0.057 * k * math.sin(a), 0.031 * k),
                  euler=_vec(0, -0.42, a), size=_vec(0.004, 0.0155 * k, 0.026 * k), rgba=colour)
    elif o.shape in ("cup", "glass"):
        alpha = 0.55 if o.shape == "glass" else 1.0
        _geom(body, name=o.name, type="cylinder", pos=_vec(0, 0, d.height / 2), size=_vec(r, d.height / 2),
              mass=_num(0.12 if o.shape == "cup" else 0.15), rgba=_rgba(o.colour, alpha))
        _geom(body, **{"class": "decor"}, type="cylinder", pos=_vec(0, 0, d.height + 0.0004),
              size=_vec(r - 0.004, 0.0006), rgba=_rgba(_shade(o.colour, 0.55), alpha))
        if o.shape == "cup":
            _geom(body, **{"class": "decor"}, type="box", pos=_vec(r + 0.008, 0, 0.55 * d.height),
                  size=_vec(0.008, 0.004, 0.25 * d.height), rgba=colour)
    elif o.shape == "utensil":
        k = s / 0.22
        _geom(body, name=f"{o.name}_head", type="box", pos=_vec(-0.045 * k, 0, 0.002),
              size=_vec(0.06 * k, 0.009, 0.002), mass=_num(0.03 * k), rgba=colour)
        _geom(body, name=f"{o.name}_tip", type="cylinder", pos=_vec(-0.105 * k, 0, 0.002), size=_vec(0.009, 0.002),
              mass="0.002", rgba=colour)
        _geom(body, name=f"{o.name}_handle", type="box", pos=_vec(0.06 * k, 0, 0.006),
              size=_vec(0.05 * k, 0.008, 0.006), mass=_num(0.04 * k), rgba=_rgba(_shade(o.colour, 0.45)))
    elif o.shape == "box":
        _geom(body, name=o.name, type="box", pos=_vec(0, 0, d.height / 2), size=_vec(r, r, d.height / 2),
              mass=_num(0.25 * (s / 0.1) ** 2), rgba=colour)
        _geom(body, **{"class": "decor"}, type="box", pos=_vec(0, 0, d.height + 0.0004), size=_vec(r - 0.006, r - 0.006,
              0.0006), rgba=_rgba(_shade(o.colour, 0.7)))
    else:
        raise ValueError(f"unknown shape {o.shape!r}")
    ET.SubElement(body, "site", {"name": f"grasp_{o.name}", "pos": _vec(*d.grasp),
                                 **({"euler": _vec(0, 0, math.pi / 2)} if o.shape != "utensil" else {}),
                                 "size": _num(d.grasp_half_width)})
    return body


def scene_xml(spec: SceneSpec) -> str:
    """The MJCF text of the scene with these objects; ValueError if they do not fit on Table A."""
    start = start_poses(spec)
    if isinstance(start, str):
        raise ValueError(start)
    root = ET.parse(SCENE_XML).getroot()
    root.set("model", "tableteach_objects")
    compiler = root.find("compiler")
    if compiler is not None:
        compiler.attrib.pop("meshdir", None)
    asset = root.find("asset")
    if asset is not None:
        for mesh in asset.findall("mesh"):
            asset.remove(mesh)
    world = root.find("worldbody")
    equality = root.find("equality")
    if world is None or equality is None:
        raise ValueError(f"{SCENE_XML.name} lacks a worldbody or equality section")
    for body in world.findall("body"):
        if body.get("name") in DINNER_OBJECTS:
            world.remove(body)
    for weld in equality.findall("weld"):
        equality.remove(weld)
    table_b = next(b for b in world.findall("body") if b.get("name") == "table_b")
    for site in table_b.findall("site"):
        table_b.remove(site)
    for o in spec.objects:
        x, y, yaw = slot_pose(o)
        attrs = {"name": f"slot_{o.name}", "pos": _vec(x - TABLE_B[0], y - TABLE_B[1], TABLE_TOP),
                "size": _num(max(dimensions(o).half_x, 0.02))}
        if yaw:
            attrs["euler"] = _vec(0, 0, yaw)
        ET.SubElement(table_b, "site", attrs)
    for o in spec.objects:
        world.append(_object_body(o, *start[o.name]))
        ET.SubElement(equality, "weld", {"name": f"grasp_{o.name}", "body1": "hand", "body2": o.name,
                                         "active": "false", "solref": "0.01 1"})
    custom = ET.SubElement(root, "custom")
    ET.SubElement(custom, "text", {"name": OBJECTS_TEXT, "data": " ".join(spec.names)})
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="unicode") + "\n"


def scene_path(spec: SceneSpec, folder: Path | str) -> Path:
    """The generated scene's file under `folder`, named by the digest of its text (written once, atomically)."""
    text = scene_xml(spec)
    digest = hashlib.sha256(text.encode()).hexdigest()[:32]
    path = Path(folder) / f"{digest}.xml"
    if not path.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
        temporary = path.with_suffix(f".{os.getpid()}.tmp")
        temporary.write_text(text, encoding="utf-8")
        os.replace(temporary, path)
    return path
