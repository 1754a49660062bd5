"""The top costs per frame of a benchmark run, from cProfile (issue 37 asks for them before and
after a change): each function's own time in microseconds per frame, the five largest, per
thread profiled. Waiting for a lock (the other thread holding the interpreter) is left out."""

from __future__ import annotations

import cProfile
import pstats
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

WAITS = ("acquire' of '_thread.lock", "wait' of '_thread")


def top_costs(profile: cProfile.Profile, frames: int, n: int = 5) -> list[tuple[str, float]]:
    """The `n` functions with the most own time: (name, us per frame)."""
    stats = pstats.Stats(profile).stats  # type: ignore[attr-defined]
    rows = []
    for (path, line, name), (_, _, tottime, _, _) in stats.items():
        where = name if path == "~" else f"{path.rsplit('/', 2)[-1]}:{line}({name})"
        if not any(w in where for w in WAITS):
            rows.append((where, tottime * 1e6 / frames))
    return sorted(rows, key=lambda r: -r[1])[:n]


def print_costs(title: str, profile: cProfile.Profile, frames: int) -> None:
    print(f"top five costs per frame, {title}:")
    for where, us in top_costs(profile, frames):
        print(f"  {us:7.3f} us  {where}")


@contextmanager
def profiled_method(cls: type, name: str) -> Iterator[cProfile.Profile]:
    """Profile every call of `cls.name` (a thread's run loop) into one profile."""
    profile = cProfile.Profile()
    original: Callable[..., Any] = getattr(cls, name)

    def wrapper(self: Any, *args: Any, **kwargs: Any) -> Any:
        return profile.runcall(original, self, *args, **kwargs)

    setattr(cls, name, wrapper)
    try:
        yield profile
    finally:
        setattr(cls, name, original)
