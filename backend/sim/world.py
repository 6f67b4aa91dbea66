"""The interface every table world offers (physics or trace-only), and its shared refusal rules."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol, runtime_checkable

#: Object names, which are also the proposition names ("<object> rests in its slot on Table B").
OBJECTS: tuple[str, ...] = ("dinner_plate", "small_plate", "bowl", "knife", "fork")


class PlacementError(ValueError):
    """A place request the world refuses: an unknown object or one the robot already moved."""


@runtime_checkable
class TableWorld(Protocol):
    """One participant's table: the robot moves objects from Table A to their slots on Table B."""

    @property
    def objects(self) -> tuple[str, ...]:
        """All object names, which are also the proposition names."""
        ...

    @property
    def trace(self) -> list[frozenset[str]]:
        """Labels of the initial state and after every action since the last reset."""
        ...

    @property
    def placed(self) -> tuple[str, ...]:
        """Objects the robot has moved off Table A (placed or dropped), in order."""
        ...

    def labels(self) -> frozenset[str]:
        """Propositions true now: the objects resting in their slots on Table B."""
        ...

    def place(self, obj: str, *, drop: bool = False) -> frozenset[str]:
        """Move `obj` to its slot (or drop it on the way if `drop`); return the labels afterwards."""
        ...

    def reset(self, seed: int = 0) -> None:
        """Put every object back on Table A (positions jittered by `seed`) and restart the trace."""
        ...

    def close(self) -> None:
        """Release whatever the world holds."""
        ...


def check_placeable(obj: str, objects: tuple[str, ...], moved: tuple[str, ...]) -> None:
    """Raise PlacementError unless `obj` is a known object still waiting on Table A."""
    waiting = [o for o in objects if o not in moved]
    if obj not in objects:
        raise PlacementError(
            f"unknown object {obj!r}: expected one of the objects on Table A: {', '.join(waiting)}"
        )
    if obj in moved:
        expected = ", ".join(waiting) if waiting else "none (all objects were moved)"
        raise PlacementError(
            f"object {obj!r} was already moved off Table A and cannot be picked up again: "
            f"expected one of the objects still on Table A: {expected}"
        )


def check_sequence(objs: Sequence[str], objects: tuple[str, ...], moved: Sequence[str] = ()) -> None:
    """Raise PlacementError unless every object can be moved in this order after `moved` (checks all first)."""
    so_far = list(moved)
    for obj in objs:
        check_placeable(obj, objects, tuple(so_far))
        so_far.append(obj)


class MoveLog:
    """What every world records the same way: the objects moved off Table A and the labels after each action.

    A world sets `_moved` and `_trace` in reset() and calls `_start_move(obj)` before it moves anything."""

    _moved: list[str]
    _trace: list[frozenset[str]]

    @property
    def objects(self) -> tuple[str, ...]:
        """All object names (the world's own)."""
        raise NotImplementedError

    @property
    def trace(self) -> list[frozenset[str]]:
        """Labels of the initial state and after every action since the last reset."""
        return list(self._trace)

    @property
    def placed(self) -> tuple[str, ...]:
        """Objects moved off Table A (placed or dropped), in order."""
        return tuple(self._moved)

    def _start_move(self, obj: str) -> None:
        """Check that `obj` can be moved now (PlacementError naming why not) and log it as moved."""
        check_placeable(obj, self.objects, tuple(self._moved))
        self._moved.append(obj)
