"""The directly serialised pose messages put on the wire exactly what viser's own serialiser puts there."""

from __future__ import annotations

import msgspec
import numpy as np
import pytest
from viser import _messages as viser_messages
from viser.infra._messages import wire_field_names

from tableteach.sim.pose_messages import SetOrientationMessage, SetPositionMessage

KINDS = [(SetPositionMessage, viser_messages.SetPositionMessage, 3),
         (SetOrientationMessage, viser_messages.SetOrientationMessage, 4)]


@pytest.mark.parametrize(("ours", "theirs", "width"), KINDS)
def test_a_pose_message_serialises_as_vipers_own(ours, theirs, width):
    rng = np.random.default_rng(width)
    for k in range(50):
        values = tuple(rng.normal(size=width).tolist())
        mine, native = ours(f"/body{k}", values), theirs(f"/body{k}", values)
        mine.owner = native.owner = f"client-{k}"
        wire, expected = mine.as_serializable_dict([]), native.as_serializable_dict([])
        assert wire == expected
        assert msgspec.msgpack.encode(wire) == msgspec.msgpack.encode(expected)  # same keys in the same order
        assert mine.redundancy_key() == native.redundancy_key()  # viser keeps the latest pose per body the same way


@pytest.mark.parametrize(("ours", "theirs", "width"), KINDS)
def test_a_pose_message_sends_every_field_viser_declares(ours, theirs, width):
    # A viser that adds a wire field to these messages must fail here, not send pages an incomplete message.
    mine = ours("/body", (0.0,) * width)
    assert set(mine.as_serializable_dict()) == set(wire_field_names(theirs)) | {"type"}
    assert type(mine).__name__ == theirs.__name__
