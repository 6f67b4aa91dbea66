"""A table world without physics: placing an object just records it (for the study server's tests)."""

from __future__ import annotations

from .world import OBJECTS, MoveLog


class TraceWorld(MoveLog):
    """TableWorld whose labels are the objects placed so far (dropped ones excluded)."""

    def __init__(self, seed: int = 0, objects: tuple[str, ...] = OBJECTS) -> None:
        self._objects = tuple(objects)
        self.reset(seed)

    @property
    def objects(self) -> tuple[str, ...]:
        """All object names."""
        return self._objects

    def labels(self) -> frozenset[str]:
        """Objects recorded as placed (not dropped)."""
        return frozenset(self._in_slot)

    def place(self, obj: str, *, drop: bool = False) -> frozenset[str]:
        """Record `obj` as placed (or as dropped, which leaves its proposition false)."""
        self._start_move(obj)
        if not drop:
            self._in_slot.add(obj)
        labels = self.labels()
        self._trace.append(labels)
        return labels

    def reset(self, seed: int = 0) -> None:
        """Forget every placement; the seed is accepted for interface parity and has no effect."""
        self._moved: list[str] = []
        self._in_slot: set[str] = set()
        self._trace = [self.labels()]

    def close(self) -> None:
        """Nothing to release."""
