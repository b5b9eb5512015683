"""The one time-series type for motion capture (after kineticstoolkit's ``TimeSeries``).

``time_s`` is 1-D in seconds; ``data`` maps a name to an array whose first axis is time (points are
``(n, 3)`` in metres); ``events`` are ``(time_s, name)`` pairs; ``info`` maps a data name to its metadata
(at least ``{"unit": ...}``). Methods return new objects.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any, NamedTuple

import numpy as np

__all__ = ["Event", "TimeSeries"]


class Event(NamedTuple):
    """A named instant, s."""

    time_s: float
    name: str


@dataclass(frozen=True, eq=False)
class TimeSeries:
    """Time-indexed arrays sharing one time axis.

    Attributes
    ----------
    time_s : float64 array, shape (n,), s, strictly increasing.
    data : name -> array of shape (n, ...).
    events : sorted `Event` tuple.
    info : name -> metadata dict, e.g. ``{"hub": {"unit": "m", "frame": "world"}}``.
    """

    time_s: np.ndarray
    data: Mapping[str, np.ndarray] = field(default_factory=dict)
    events: tuple[Event, ...] = ()
    info: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        t = np.asarray(self.time_s, dtype=np.float64)
        if t.ndim != 1:
            raise ValueError(f"time_s must be 1-D, got shape {t.shape}")
        if t.size > 1 and not np.all(np.diff(t) > 0):
            raise ValueError("time_s must be strictly increasing")
        object.__setattr__(self, "time_s", t)
        for k, v in self.data.items():
            if np.shape(v)[:1] != t.shape:
                raise ValueError(f"data[{k!r}] has first axis {np.shape(v)[:1]}, time has {t.shape}")
        object.__setattr__(self, "data", dict(self.data))
        ev = self.events
        if not (
            isinstance(ev, tuple) and all(type(e) is Event for e in ev) and all(a <= b for a, b in zip(ev, ev[1:]))
        ):  # already sorted Events: kept as they are
            ev = tuple(sorted(Event(float(a), str(b)) for a, b in ev))
        object.__setattr__(self, "events", ev)
        object.__setattr__(self, "info", {k: dict(v) for k, v in self.info.items()})

    def __len__(self) -> int:
        return int(self.time_s.size)

    def __getitem__(self, key: str) -> np.ndarray:
        return self.data[key]

    def add_data(self, name: str, values: np.ndarray, **info: Any) -> TimeSeries:
        """A copy with one more (or replaced) data array and its info (e.g. ``unit="m"``)."""
        data = dict(self.data)
        data[name] = np.asarray(values)
        new_info = dict(self.info)
        new_info[name] = dict(info)
        return replace(self, data=data, info=new_info)

    def add_event(self, time_s: float, name: str) -> TimeSeries:
        """A copy with one more event."""
        return replace(self, events=(*self.events, Event(time_s, name)))

    def get_event_times(self, name: str) -> np.ndarray:
        """Times of all events called ``name``, s, sorted."""
        return np.array([e.time_s for e in self.events if e.name == name], dtype=np.float64)

    def get_index_at_time(self, time_s: float) -> int:
        """Index of the sample nearest to ``time_s``."""
        return int(np.argmin(np.abs(self.time_s - time_s)))

    def get_ts_between_times(self, t0_s: float, t1_s: float) -> TimeSeries:
        """A copy restricted to ``t0_s <= t <= t1_s`` (events too)."""
        m = (self.time_s >= t0_s) & (self.time_s <= t1_s)
        return TimeSeries(
            self.time_s[m],
            {k: v[m] for k, v in self.data.items()},
            tuple(e for e in self.events if t0_s <= e.time_s <= t1_s),
            self.info,
        )
