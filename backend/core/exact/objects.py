"""A dinner-like task over the objects a user names: each may be required, ordered or forbidden."""

from __future__ import annotations

import re
from functools import lru_cache

from ..domain import Domain, get_domain, objects_task
from ..ltl import KEYWORDS
from .learner import MAX_OBJECTS, MIN_OBJECTS

NAME = re.compile(r"[a-z][a-z0-9_]*")


def parse_objects(text: str) -> tuple[str, ...]:
    """Object names from 'a,b,c': 2 to 10 distinct lower-case names; ValueError naming the problem."""
    names = tuple(part.strip() for part in text.split(","))
    if not MIN_OBJECTS <= len(names) <= MAX_OBJECTS:
        raise ValueError(
            f"--objects: {len(names)} names given; expected {MIN_OBJECTS} to {MAX_OBJECTS}, comma-separated"
        )
    for name in names:
        if not NAME.fullmatch(name) or name in KEYWORDS:
            raise ValueError(
                f"--objects: {name!r} is not a valid object name; expected lower-case letters, digits and _, "
                f"starting with a letter"
            )
    duplicates = sorted({n for n in names if names.count(n) > 1})
    if duplicates:
        raise ValueError(f"--objects: {', '.join(duplicates)} named more than once; expected distinct names")
    return names


@lru_cache(maxsize=16)
def objects_domain(names: tuple[str, ...]) -> Domain:
    """The task of placing these objects, each at most once, in any order (the dinner table's dynamics)."""
    return get_domain(objects_task(names))
