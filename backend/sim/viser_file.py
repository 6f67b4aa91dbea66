"""viser 1.1's .viser file (what its browser client plays with `?playbackPath=`), read and written directly.

The layout is viser's own (viser.infra.StateSerializer.serialize): an 8-byte little-endian size of the inner
payload, then the inner payload zstd-compressed; the inner payload is an 8-byte little-endian msgpack length,
the msgpack map {durationSeconds, messages, viserVersion, binaryBufferLengths}, then the binary buffers, each
8-byte aligned. `messages` is a list of (playback time, message dict); a dict's numpy arrays are placeholders
{"__binary_index": i, "dtype": ...} into the buffers. Writing it here lets the robot's recordings be encoded
from numpy arrays without re-posing a viser scene frame by frame.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import msgspec
import numpy as np
import viser
import zstandard

ALIGNMENT = 8
# viser uses level 12 with one thread per core; level 1 makes a file about 3% larger for a tenth of the CPU.
COMPRESSION_LEVEL = 1

Message = dict[str, Any]
Timed = tuple[float, Message]


@dataclass(frozen=True)
class Encoded:
    """`count` consecutive entries of a file's message list, already in msgpack."""

    data: bytes
    count: int


@dataclass(frozen=True)
class ViserFile:
    """A .viser recording: its messages at their playback times (decode gives dicts only), its length in seconds
    and its binary buffers."""

    duration: float
    messages: list[Timed | Encoded]
    buffers: list[bytes]
    version: str = viser.__version__


def decode(data: bytes) -> ViserFile:
    """Read a .viser file (ValueError if it is not one)."""
    if len(data) < 8:
        raise ValueError(f"{len(data)} bytes: expected a .viser file (an 8-byte size, then zstd data)")
    size = int.from_bytes(data[:8], "little")
    try:
        inner = zstandard.ZstdDecompressor().decompress(data[8:], max_output_size=size)
    except zstandard.ZstdError as exc:
        raise ValueError(f"the .viser payload does not decompress: {exc}") from exc
    length = int.from_bytes(inner[:8], "little")
    payload = msgspec.msgpack.decode(inner[8 : 8 + length])
    offset, buffers = 8 + length, []
    for nbytes in payload["binaryBufferLengths"]:
        offset += (ALIGNMENT - offset % ALIGNMENT) % ALIGNMENT
        buffers.append(bytes(inner[offset : offset + nbytes]))
        offset += nbytes
    messages: list[Timed | Encoded] = [(float(t), m) for t, m in payload["messages"]]
    return ViserFile(float(payload["durationSeconds"]), messages, buffers, str(payload["viserVersion"]))


def _array_header(n: int) -> bytes:
    if n < 16:
        return bytes([0x90 | n])
    return b"\xdc" + n.to_bytes(2, "big") if n < 2**16 else b"\xdd" + n.to_bytes(4, "big")


def encode_messages(messages: Sequence[Timed | Encoded]) -> Encoded:
    """A message list (dicts and encoded runs) as one encoded run."""
    encoder = msgspec.msgpack.Encoder()
    parts, count = [], 0
    for item in messages:
        if isinstance(item, Encoded):
            parts.append(item.data)
            count += item.count
        else:
            parts.append(encoder.encode(item))
            count += 1
    return Encoded(b"".join(parts), count)


def encode(recording: ViserFile, level: int = COMPRESSION_LEVEL) -> bytes:
    """The .viser bytes of a recording, in viser's layout."""
    encoder = msgspec.msgpack.Encoder()
    messages = encode_messages(recording.messages)
    # the map viser writes, {durationSeconds, messages, viserVersion, binaryBufferLengths}, around encoded runs
    payload = b"".join([
        b"\x84", encoder.encode("durationSeconds"), encoder.encode(recording.duration),
        encoder.encode("messages"), _array_header(messages.count), messages.data,
        encoder.encode("viserVersion"), encoder.encode(recording.version),
        encoder.encode("binaryBufferLengths"), encoder.encode([len(b) for b in recording.buffers]),
    ])
    parts: list[bytes] = [len(payload).to_bytes(8, "little"), payload]
    offset = 8 + len(payload)
    for buf in recording.buffers:
        padding = (ALIGNMENT - offset % ALIGNMENT) % ALIGNMENT
        parts += [b"\0" * padding, buf]
        offset += padding + len(buf)
    inner = b"".join(parts)
    return len(inner).to_bytes(8, "little") + zstandard.ZstdCompressor(level=level).compress(inner)


def set_position(name: str, position: Sequence[float]) -> Message:
    """viser's SetPositionMessage as it is written into a file."""
    return {"name": name, "position": list(position), "owner": "", "type": "SetPositionMessage"}


def set_orientation(name: str, wxyz: Sequence[float]) -> Message:
    """viser's SetOrientationMessage as it is written into a file."""
    return {"name": name, "wxyz": list(wxyz), "owner": "", "type": "SetOrientationMessage"}


def set_text(name: str, text: str) -> Message:
    """viser's SceneNodeUpdateMessage changing a label's text."""
    return {"name": name, "updates": {"text": text}, "owner": "", "type": "SceneNodeUpdateMessage"}


def set_visible(name: str, visible: bool) -> Message:
    """viser's SetSceneNodeVisibilityMessage."""
    return {"name": name, "visible": visible, "owner": "", "type": "SetSceneNodeVisibilityMessage"}


_SENTINELS = (1.5, 2.5, 3.5, 4.5, 5.5)  # distinct floats whose encodings mark a template's slots


@lru_cache(maxsize=1024)
def _template(name: str, position: bool) -> tuple[np.ndarray, np.ndarray]:
    """msgpack of one (time, pose message) of a node, and the offsets of its time and value floats' 8 bytes."""
    n = 3 if position else 4
    values = _SENTINELS[1 : 1 + n]
    message = set_position(name, values) if position else set_orientation(name, values)
    raw = msgspec.msgpack.encode((_SENTINELS[0], message))
    slots = [raw.index(b"\xcb" + struct.pack(">d", v)) + 1 for v in _SENTINELS[: 1 + n]]
    return np.frombuffer(raw, dtype=np.uint8), np.array(slots)


def pose_messages(names: Sequence[str], times: np.ndarray, node: np.ndarray, position: np.ndarray,
                  values: np.ndarray) -> Encoded:
    """Row k as (times[k], SetPositionMessage of names[node[k]] to values[k, :3]) if position[k], else
    (times[k], SetOrientationMessage to values[k, :4]), encoded as msgspec encodes them, without one Python
    object per message."""
    count = len(times)
    if count == 0:
        return Encoded(b"", 0)
    group = 2 * np.asarray(node) + np.where(position, 0, 1)
    kinds = np.unique(group)
    templates = {int(g): _template(names[g // 2], g % 2 == 0) for g in kinds}
    sizes = np.zeros(int(kinds.max()) + 1, dtype=np.int64)
    for g, (raw, _slots) in templates.items():
        sizes[g] = len(raw)
    length = sizes[group]
    start = np.cumsum(length) - length
    out = np.empty(int(length.sum()), dtype=np.uint8)
    fields = np.empty((count, 5, 8), dtype=np.uint8)  # the time, then up to four values, big-endian
    fields[:, 0] = np.ascontiguousarray(times, dtype=">f8").view(np.uint8).reshape(count, 8)
    fields[:, 1:] = np.ascontiguousarray(values[:, :4], dtype=">f8").view(np.uint8).reshape(count, 4, 8)
    for g, (raw, slots) in templates.items():
        rows = np.flatnonzero(group == g)
        base = start[rows][:, None]
        out[base + np.arange(len(raw))] = raw
        out[base[:, :, None] + slots[None, :, None] + np.arange(8)] = fields[rows, : len(slots)]
    return Encoded(out.tobytes(), count)
