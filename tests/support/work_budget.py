"""A budget of work, counted in function calls, for tests that check that something does not hang or blow up:
unlike a bound on the wall clock, the count is the same on a fast and on a busy machine."""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Callable, Iterator
from typing import Any


class WorkBudgetExceeded(AssertionError):
    """The block made more calls than its budget: it hangs, or its work grew beyond what it should do."""


@contextlib.contextmanager
def call_budget(max_calls: int) -> Iterator[Callable[[], int]]:
    """Count the calls (Python functions and calls into C) this thread makes in the block; past `max_calls`,
    stop the block with `WorkBudgetExceeded`. Yields a function that returns the count so far."""
    count = 0
    before = sys.getprofile()

    def profile(frame: Any, event: str, arg: Any) -> None:
        nonlocal count
        if event == "call" or event == "c_call":
            count += 1
            if count > max_calls:
                sys.setprofile(before)
                raise WorkBudgetExceeded(f"more than {max_calls} calls: a hang, or work out of proportion")

    sys.setprofile(profile)
    try:
        yield lambda: count
    finally:
        sys.setprofile(before)
