"""viser's two pose messages with a direct serialiser: what they put on the wire is what viser's own give.

viser serialises a message by walking its type hints (about 4 us a message); a moving robot sends two per body
and frame to every browser watching, so that walk was over a quarter of viser's websocket thread. These subclasses keep
viser's class names (its redundancy keys and the page's message types depend on them) and build the same dict
directly (about 0.2 us). tests/sim/test_pose_messages.py compares them with viser's serialiser."""

from __future__ import annotations

from typing import Any

from viser import _messages as viser_messages


class SetPositionMessage(viser_messages.SetPositionMessage):
    """viser's SetPositionMessage, serialised directly; `position` must hold three Python floats."""

    def as_serializable_dict(self, binary_buffers: list[memoryview] | None = None) -> dict[str, Any]:
        """The dict viser's serialiser builds for this message."""
        return {"name": self.name, "position": self.position, "owner": self.owner, "type": "SetPositionMessage"}


class SetOrientationMessage(viser_messages.SetOrientationMessage):
    """viser's SetOrientationMessage, serialised directly; `wxyz` must hold four Python floats."""

    def as_serializable_dict(self, binary_buffers: list[memoryview] | None = None) -> dict[str, Any]:
        """The dict viser's serialiser builds for this message."""
        return {"name": self.name, "wxyz": self.wxyz, "owner": self.owner, "type": "SetOrientationMessage"}
