"""Mirror the MuJoCo scene into viser scenes: one frame per body, one child primitive per visible geom, and only
changed body poses pushed per frame (BodyMirror); SceneView is a whole scene on a viser server of its own."""

from __future__ import annotations

import threading
from functools import lru_cache
from typing import Any
from collections.abc import Callable, Iterable, Sequence

import mujoco
import numpy as np
import viser

from .pose_messages import SetOrientationMessage, SetPositionMessage
from .scene import scene_objects
from .world import OBJECTS

POSE_EPSILON = 1e-4  # pose change (m or quaternion units) below which a body is not re-sent
HIDDEN_GROUP = 3  # geoms in this group and above are collision-only (see scene.xml)
TABLE_LABELS = {"table_a": "Table A", "table_b": "Table B"}  # as the participant's instructions name them
OBJECT_LABEL_HEIGHT = 0.02  # m above an object's centre; the label hangs below that point on screen, away from the arm
CAPTION_NODE = "/caption"  # the scene node of the one-line status (recordings change its text)
SKY_LIGHT = "/sky_light"  # the scene node of the light from above (prepare_server)


@lru_cache(maxsize=64)
def capsule_mesh(
    radius: float, half_length: float, segments: int = 20, rings: int = 6
) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and faces of a z-aligned capsule (viser has no capsule primitive); read-only, made once per shape
    because every browser's own scene holds the arm's capsules."""
    angles = np.linspace(0.0, np.pi / 2, rings + 1)
    upper = [(radius * np.cos(a), half_length + radius * np.sin(a)) for a in angles]
    profile = [(r, -z) for r, z in reversed(upper)] + upper
    vertices, faces = [], []
    for r, z in profile:
        for k in range(segments):
            t = 2 * np.pi * k / segments
            vertices.append((r * np.cos(t), r * np.sin(t), z))
    for i in range(len(profile) - 1):
        for k in range(segments):
            a, b = i * segments + k, i * segments + (k + 1) % segments
            c, d = b + segments, a + segments
            faces += [(a, b, c), (a, c, d)]
    vertex_array, face_array = np.asarray(vertices, dtype=np.float32), np.asarray(faces, dtype=np.uint32)
    vertex_array.flags.writeable = face_array.flags.writeable = False
    return vertex_array, face_array


def _rgb(model: mujoco.MjModel, geom: int) -> tuple[tuple[int, int, int], float]:
    rgba = model.mat_rgba[model.geom_matid[geom]] if model.geom_matid[geom] >= 0 else model.geom_rgba[geom]
    return tuple(int(round(255 * c)) for c in rgba[:3]), float(rgba[3])  # type: ignore[return-value]


def moving_bodies(model: mujoco.MjModel) -> frozenset[str]:
    """Bodies that can move (not welded to the world): the arm and the objects."""
    return frozenset(model.body(b).name for b in range(model.nbody) if model.body_weldid[b] != 0)


def _close(new: list[float], shown: list[float]) -> bool:
    """np.allclose(new, shown) for short lists, as viser's setters decide that nothing changed (NaN is never close)."""
    for a, b in zip(new, shown, strict=True):
        if not abs(a - b) <= 1e-8 + 1e-5 * abs(b):
            return False
    return True


def fast_pose_writer(frame: viser.FrameHandle) -> Callable[[np.ndarray], None] | None:
    """A writer of a frame's (x, y, z, qw, qx, qy, qz) that queues viser's two pose messages directly, or None when
    this viser does not have the private parts it needs (then the public setters are used).

    viser 1.1's pose setters check each value against the last with np.allclose and validate it first: two thirds
    of the CPU of a moving robot's live view. BodyMirror compares poses itself, all bodies at once, so the writer
    does what the setters do after their validation: skip a part that is np.allclose to the handle's, else update
    the handle's array and queue the same message (stamped with the scene's owner by _queue_scene_message), one
    that serialises itself directly (pose_messages.py). tests/sim/test_view.py fails if the messages differ."""
    impl = getattr(frame, "_impl", None)
    api = getattr(impl, "api", None)
    queue = getattr(api, "_queue_scene_message", None)
    if impl is None or queue is None or not hasattr(impl, "position") or not hasattr(impl, "wxyz"):
        return None
    name = impl.name
    shown = [impl.position.tolist(), impl.wxyz.tolist()]  # the handle's arrays as lists: compared every frame

    def write(pose: np.ndarray) -> None:
        moved, turned = write_pose(name, pose.tolist(), shown, queue)
        if moved:
            impl.position[:] = shown[0]
        if turned:
            impl.wxyz[:] = shown[1]

    return write


def write_pose(name: str, values: list[Any], shown: list[list[float]],
               queue: Callable[[Any], None]) -> tuple[bool, bool]:
    """Queue the pose messages of a node whose browser has shown = [position, wxyz] (lists, replaced when sent), as
    viser's setters do: a part np.allclose to what the browser has is not sent. Whether each part was sent."""
    position, wxyz = values[:3], values[3:]
    moved = not _close(position, shown[0])
    if moved:
        shown[0] = position
        queue(SetPositionMessage(name, tuple(position)))
    turned = not _close(wxyz, shown[1])
    if turned:
        shown[1] = wxyz
        queue(SetOrientationMessage(name, tuple(wxyz)))
    return moved, turned


BodyIndex = tuple[np.ndarray, np.ndarray]  # positions in a pose list, and the mirror's rows of those bodies


def body_index(cache: dict[tuple[str, ...], BodyIndex], rows: dict[str, int], bodies: Sequence[str]) -> BodyIndex:
    """Which of these bodies a mirror holds, and their rows (kept in `cache`: the list is nearly always the same)."""
    key = tuple(bodies)
    index = cache.get(key)
    if index is None:
        pairs = [(i, rows[name]) for i, name in enumerate(key) if name in rows]
        index = (np.array([i for i, _ in pairs], dtype=int), np.array([r for _, r in pairs], dtype=int))
        cache[key] = index
    return index


def changed_poses(last: np.ndarray, index: BodyIndex, poses: np.ndarray) -> list[tuple[int, np.ndarray]]:
    """(row, pose) of each body whose pose moved POSE_EPSILON or more from its row of `last`."""
    given, rows = index
    wanted = np.asarray(poses, dtype=float)[given]
    changed = np.flatnonzero(np.max(np.abs(wanted - last[rows]), axis=1, initial=0.0) >= POSE_EPSILON)
    return [(int(rows[k]), wanted[k]) for k in changed.tolist()]


class BodyMirror:
    """MuJoCo bodies mirrored into one viser scene (the view hub's shared one, a SceneView's, or the recorder that
    client_scene's templates are made with): a frame per body, a child primitive per visible geom, and only changed
    poses pushed."""

    def __init__(self, scene: viser.SceneApi, model: mujoco.MjModel, data: mujoco.MjData,
                 bodies: Iterable[str] | None = None) -> None:
        self.scene = scene
        self.frames: dict[str, viser.FrameHandle] = {}
        self.geoms: dict[str, list[Any]] = {}  # viser's clickable handles (no public base type)
        self._rows: dict[str, int] = {}  # body -> its row of _last
        last: list[np.ndarray] = []
        wanted = None if bodies is None else set(bodies)
        self._objects = frozenset(scene_objects(model))
        for b in range(model.nbody):
            if wanted is None or model.body(b).name in wanted:
                last.append(self._add_body(model, data, b))
        self._last = np.array(last, dtype=float).reshape(len(last), 7)
        self._names = list(self.frames)
        self._writers = [fast_pose_writer(self.frames[name]) for name in self._names]
        self._index_cache: dict[tuple[str, ...], BodyIndex] = {}

    def _add_body(self, model: mujoco.MjModel, data: mujoco.MjData, body: int) -> np.ndarray:
        """Add one body's frame, geoms and label; its pose now."""
        name = model.body(body).name
        frame = self.scene.add_frame(
            f"/{name}", show_axes=False, position=data.xpos[body].copy(), wxyz=data.xquat[body].copy()
        )
        self._rows[name] = len(self.frames)
        self.frames[name] = frame
        self.geoms[name] = []
        for g in np.flatnonzero(model.geom_bodyid == body):
            handle = add_geom(self.scene, model, int(g), f"/{name}/g{g}")
            if handle is not None:
                self.geoms[name].append(handle)
        if name in self._objects:
            add_object_label(self.scene, name)
        return np.concatenate([data.xpos[body], data.xquat[body]])

    def pose_of(self, body: str) -> np.ndarray:
        """The last pose pushed for a body (x, y, z, qw, qx, qy, qz)."""
        return self._last[self._rows[body]].copy()

    def set_poses(self, bodies: Sequence[str], poses: np.ndarray) -> int:
        """Push (x, y, z, qw, qx, qy, qz) per body this mirror holds, skipping unchanged ones; how many were sent."""
        changed = changed_poses(self._last, body_index(self._index_cache, self._rows, bodies), poses)
        for row, pose in changed:
            write = self._writers[row]
            if write is not None:
                write(pose)
            else:
                frame = self.frames[self._names[row]]
                frame.position = pose[:3]
                frame.wxyz = pose[3:]
            self._last[row] = pose
        return len(changed)


def add_geom(scene: viser.SceneApi, model: mujoco.MjModel, g: int, path: str) -> Any:
    """One MuJoCo geom as a viser primitive at its local pose (None for collision-only or invisible geoms)."""
    color, alpha = _rgb(model, g)
    if model.geom_group[g] >= HIDDEN_GROUP or alpha == 0.0:
        return None
    size = model.geom_size[g]
    pose = dict(position=model.geom_pos[g].copy(), wxyz=model.geom_quat[g].copy())
    opacity = None if alpha >= 1.0 else alpha
    kind = model.geom_type[g]
    if kind == mujoco.mjtGeom.mjGEOM_PLANE:
        return scene.add_box(path, color=color, dimensions=(2 * size[0], 2 * size[1], 0.002), **pose)
    if kind == mujoco.mjtGeom.mjGEOM_BOX:
        return scene.add_box(path, color=color, dimensions=tuple(2 * size), opacity=opacity, **pose)
    if kind == mujoco.mjtGeom.mjGEOM_SPHERE:
        return scene.add_icosphere(path, radius=float(size[0]), color=color, opacity=opacity, **pose)
    if kind == mujoco.mjtGeom.mjGEOM_ELLIPSOID:
        return scene.add_icosphere(path, radius=1.0, scale=tuple(size), color=color, opacity=opacity, **pose)
    if kind == mujoco.mjtGeom.mjGEOM_CYLINDER:
        return scene.add_cylinder(
            path, radius=float(size[0]), height=float(2 * size[1]), color=color, opacity=opacity, **pose
        )
    if kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
        vertices, faces = capsule_mesh(float(size[0]), float(size[1]))
        return scene.add_mesh_simple(path, vertices, faces, color=color, opacity=opacity, **pose)
    if kind == mujoco.mjtGeom.mjGEOM_MESH:
        mesh = model.geom_dataid[g]
        v0, nv = model.mesh_vertadr[mesh], model.mesh_vertnum[mesh]
        f0, nf = model.mesh_faceadr[mesh], model.mesh_facenum[mesh]
        return scene.add_mesh_simple(
            path, model.mesh_vert[v0 : v0 + nv], model.mesh_face[f0 : f0 + nf], color=color,
            opacity=opacity, side="double", **pose,
        )
    raise ValueError(f"geom {g} has type {kind}: expected plane, box, sphere, ellipsoid, cylinder, capsule or mesh")


def prepare_server(server: viser.ViserServer, model: mujoco.MjModel, camera: str = "overview") -> None:
    """A new viser server's look for participants: no logo or share button, the panel folded, the initial camera,
    and lights that software WebGL draws cheaply (see SKY_LIGHT)."""
    server.gui.configure_theme(show_logo=False, show_share_button=False)
    server.gui.main_panel.minimize()
    # Three 1024-pixel shadow maps drawn every frame were two thirds of a frame's cost with software WebGL; the
    # soft shadows under the objects are what is given up.
    server.scene.configure_default_lights(enabled=True, cast_shadow=False)
    # viser's default environment map is an HDR JPEG its client decodes through WebGL and reads back: with software
    # WebGL that blocked the page 4-9 s at every load of the view (live or a recording), enough for the page's stall
    # watch to switch to 2D. A hemisphere light from above lights the scene about as the map did.
    server.scene.configure_environment_map(hdri=None)
    server.scene.add_light_hemisphere(SKY_LIGHT, sky_color=(235, 242, 255), ground_color=(180, 180, 180),
                                      intensity=3.0, position=(0.0, 0.0, 1.0))
    initial_camera(server, model, camera)


def initial_camera(server: viser.ViserServer, model: mujoco.MjModel, camera: str = "overview") -> None:
    """Point the server's initial camera through the scene's named camera at the table tops."""
    cam = model.camera(camera)
    forward = -cam.mat0.reshape(3, 3)[:, 2]
    # Aim where the view axis meets the table-top plane (z = 0.4).
    distance = (cam.pos[2] - 0.4) / max(-forward[2], 1e-3)
    server.initial_camera.position = tuple(cam.pos)
    server.initial_camera.look_at = tuple(cam.pos + distance * forward)
    server.initial_camera.fov = float(np.deg2rad(model.cam_fovy[cam.id]))


def add_table_labels(scene: viser.SceneApi, model: mujoco.MjModel, data: mujoco.MjData) -> None:
    """"Table A" and "Table B" at the front edge of each table top, the words the instructions use."""
    for body, text in TABLE_LABELS.items():
        try:
            b = model.body(body).id
        except KeyError:
            continue  # a scene without that table
        geoms = np.flatnonzero(model.geom_bodyid == b)
        tops = [g for g in geoms if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX]
        if not tops:
            continue
        g = max(tops, key=lambda k: model.geom_pos[k][2])
        x, y, _ = data.xpos[b] + model.geom_pos[g]
        top = data.xpos[b][2] + model.geom_pos[g][2] + model.geom_size[g][2]
        front = x + model.geom_size[g][0]  # the camera looks from +x
        scene.add_label(f"/labels/{body}", text, position=(float(front) + 0.02, float(y), float(top)),
                        anchor="top-center", font_screen_scale=1.1)


def add_object_label(scene: viser.SceneApi, name: str) -> viser.LabelHandle:
    """The object's name on it (a child of its frame, so it moves with it), hanging below it on screen: the arm
    reaches objects from above, so the name is rarely under the arm."""
    return scene.add_label(f"/{name}/label", name.replace("_", " "), position=(0.0, 0.0, OBJECT_LABEL_HEIGHT),
                           anchor="top-center", font_screen_scale=1.0)


def add_caption(scene: viser.SceneApi) -> viser.LabelHandle:
    """The one-line status above the tables (hidden while empty)."""
    return scene.add_label(CAPTION_NODE, "", position=(0.7, 0.0, 0.06), anchor="top-center", font_screen_scale=1.3,
                           visible=False)


class SceneView:
    """One viser server on 127.0.0.1 showing one scene to every client (the studio that records .viser files,
    and tools); close() releases its port."""

    def __init__(
        self,
        model: mujoco.MjModel,
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        clickable: Iterable[str] = OBJECTS,
        on_click: Callable[[str], None] | None = None,
        camera: str = "overview",
    ) -> None:
        self.server = viser.ViserServer(host=host, port=port, verbose=False)
        self._on_click = on_click
        self._lock = threading.Lock()
        prepare_server(self.server, model, camera)
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        self._mirror = BodyMirror(self.server.scene, model, data)
        self._geoms = self._mirror.geoms
        self._caption = add_caption(self.server.scene)
        add_table_labels(self.server.scene, model, data)
        self._clickable: set[str] = set()
        for obj in clickable:
            self.set_clickable(obj, True)

    @property
    def port(self) -> int:
        """The TCP port the viser server listens on."""
        return self.server.get_port()

    @property
    def url(self) -> str:
        """Address of viser's page for this view."""
        return f"http://127.0.0.1:{self.port}/"

    @property
    def client_count(self) -> int:
        """Browsers connected right now."""
        return len(self.server.get_clients())

    # -- interaction ------------------------------------------------------------------------------
    def set_clickable(self, obj: str, clickable: bool) -> None:
        """Make an object clickable (outlined on hover, reports clicks) or not."""
        if obj not in self._geoms:
            raise ValueError(f"unknown object {obj!r}: expected a body of the scene, e.g. one of {OBJECTS}")
        with self._lock:
            if clickable == (obj in self._clickable):
                return
            for handle in self._geoms[obj]:
                if clickable:
                    handle.on_click(lambda _event, name=obj: self._clicked(name))
                else:
                    handle.remove_click_callback("all")
            (self._clickable.add if clickable else self._clickable.discard)(obj)

    @property
    def clickable(self) -> frozenset[str]:
        """Objects that currently report clicks."""
        return frozenset(self._clickable)

    def _clicked(self, obj: str) -> None:
        if self._on_click is not None and obj in self._clickable:
            self._on_click(obj)

    def set_caption(self, text: str) -> None:
        """Show a one-line status above the tables (empty text hides it)."""
        self._caption.text = text
        self._caption.visible = bool(text)

    # -- poses -------------------------------------------------------------------------------------
    def set_poses(self, bodies: Sequence[str], poses: np.ndarray) -> int:
        """Push (x, y, z, qw, qx, qy, qz) per body, skipping unchanged ones; return how many were sent."""
        with self.server.atomic():
            return self._mirror.set_poses(bodies, poses)

    def close(self) -> None:
        """Stop the server: its threads end and its port is released."""
        self.server.stop()
