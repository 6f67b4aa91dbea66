"""Mirror the MuJoCo scene in a viser server for one participant: one frame per body, one child
primitive per visible geom, and only changed body poses pushed per frame."""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable, Sequence

import mujoco
import numpy as np
import viser

from .world import OBJECTS

POSE_EPSILON = 1e-4  # pose change (m or quaternion units) below which a body is not re-sent
HIDDEN_GROUP = 3  # geoms in this group and above are collision-only (see scene.xml)
TABLE_LABELS = {"table_a": "Table A", "table_b": "Table B"}  # as the participant's instructions name them


def capsule_mesh(
    radius: float, half_length: float, segments: int = 20, rings: int = 6
) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and faces of a z-aligned capsule (viser has no capsule primitive)."""
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
    return np.asarray(vertices, dtype=np.float32), np.asarray(faces, dtype=np.uint32)


def _rgb(model: mujoco.MjModel, geom: int) -> tuple[tuple[int, int, int], float]:
    rgba = model.mat_rgba[model.geom_matid[geom]] if model.geom_matid[geom] >= 0 else model.geom_rgba[geom]
    return tuple(int(round(255 * c)) for c in rgba[:3]), float(rgba[3])  # type: ignore[return-value]


class SceneView:
    """One viser server on 127.0.0.1 showing one participant's table; close() releases its port."""

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
        self.server.gui.configure_theme(show_logo=False, show_share_button=False)
        self.server.gui.main_panel.minimize()
        self._set_camera(model, camera)
        self._frames: dict[str, viser.FrameHandle] = {}
        self._geoms: dict[str, list[viser.SceneNodeHandle]] = {}
        self._last: dict[str, np.ndarray] = {}
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        for b in range(model.nbody):
            self._add_body(model, data, b)
        self._caption = self.server.scene.add_label(
            "/caption", "", position=(0.7, 0.0, 0.06), anchor="top-center", font_screen_scale=1.3, visible=False
        )
        self._add_table_labels(model, data)
        self._clickable: set[str] = set()
        for obj in clickable:
            self.set_clickable(obj, True)
        self._index_cache: dict[tuple[str, ...], list[tuple[int, str]]] = {}

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

    def _set_camera(self, model: mujoco.MjModel, camera: str) -> None:
        cam = model.camera(camera)
        forward = -cam.mat0.reshape(3, 3)[:, 2]
        # Aim where the view axis meets the table-top plane (z = 0.4).
        distance = (cam.pos[2] - 0.4) / max(-forward[2], 1e-3)
        self.server.initial_camera.position = tuple(cam.pos)
        self.server.initial_camera.look_at = tuple(cam.pos + distance * forward)
        self.server.initial_camera.fov = float(np.deg2rad(model.cam_fovy[cam.id]))

    def _add_body(self, model: mujoco.MjModel, data: mujoco.MjData, body: int) -> None:
        name = model.body(body).name
        frame = self.server.scene.add_frame(
            f"/{name}", show_axes=False, position=data.xpos[body].copy(), wxyz=data.xquat[body].copy()
        )
        self._frames[name] = frame
        self._last[name] = np.concatenate([data.xpos[body], data.xquat[body]])
        self._geoms[name] = []
        for g in np.flatnonzero(model.geom_bodyid == body):
            handle = self._add_geom(model, int(g), f"/{name}/g{g}")
            if handle is not None:
                self._geoms[name].append(handle)

    def _add_geom(self, model: mujoco.MjModel, g: int, path: str) -> viser.SceneNodeHandle | None:
        color, alpha = _rgb(model, g)
        if model.geom_group[g] >= HIDDEN_GROUP or alpha == 0.0:
            return None
        size = model.geom_size[g]
        pose = dict(position=model.geom_pos[g].copy(), wxyz=model.geom_quat[g].copy())
        opacity = None if alpha >= 1.0 else alpha
        scene, kind = self.server.scene, model.geom_type[g]
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

    def _add_table_labels(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
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
            self.server.scene.add_label(f"/labels/{body}", text, position=(float(front) + 0.02, float(y), float(top)),
                                        anchor="top-center", font_screen_scale=1.1)

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
        key = tuple(bodies)
        index = self._index_cache.get(key)
        if index is None:
            index = [(i, name) for i, name in enumerate(key) if name in self._frames]
            self._index_cache[key] = index
        sent = 0
        with self.server.atomic():
            for i, name in index:
                pose = poses[i]
                last = self._last[name]
                if np.max(np.abs(pose - last)) < POSE_EPSILON:
                    continue
                frame = self._frames[name]
                frame.position = pose[:3]
                frame.wxyz = pose[3:]
                self._last[name] = pose.copy()
                sent += 1
        return sent

    def close(self) -> None:
        """Stop the server: its threads end and its port is released."""
        self.server.stop()
