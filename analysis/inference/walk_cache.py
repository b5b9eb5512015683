"""The calibration's cache of simulated walks: the most recently used kept, bounded in count and in bytes.

A walk the calibration records (`rimless.analysis.inference.calibrate._Sim.walk`) holds its CoM table at every
integrator point: 40k-90k rows, 2-4 MB, on a light-legged wheel (m = 0.1 g, the audit's), and its steps' state
segments as much again, which the calibration does not read once the table is made (they are dropped before
caching). A Table 1 wheel's walk of 12 steps holds 1.4k rows, 89 kB. The cache serves the evaluations a few
walks apart: a change of a trial's time shift alone (each Jacobian's last columns, 2 n_t (1 + n_g) walks after
the trial's first: two walks an evaluation, the release step's and the one extended to cover the window), the
RMS rows at the solution. The previous cache (257 walks, first in first out, segments kept) held about 2.4 GB
after 21 min of a 5000-simulation calibration of 4 light-legged trials; this one keeps at most
`WALK_CACHE_BYTES` (about 110 light-leg walks, 5 Jacobians' worth of those 4 trials) and `WALK_CACHE_WALKS`
(more than the 257 before, for small walks). A walk evicted and needed again is simulated again (it counts
against the simulation budget).
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Hashable
from typing import Any

import numpy as np

__all__ = ["WALK_CACHE_WALKS", "WALK_CACHE_BYTES", "WalkCache", "walk_nbytes"]

#: at most this many walks are kept (a central-difference Jacobian of 12 trials and 3 fitted parameters records
#: 2 x 12 x 8 = 192 walks between a trial's first walk and its time shift's column)
WALK_CACHE_WALKS = 512
#: and at most this many bytes of their arrays (`walk_nbytes`: 5.8k Table 1 walks, about 110 light-leg walks)
WALK_CACHE_BYTES = 512 * 2**20


#: bytes per table row of the CoM curve's parts the calibration attaches to a walk when it first reads it
#: (`rimless.analysis.inference.calibrate._hermite_parts`: time, height, rate and a flag per sample, at most)
HERMITE_BYTES_PER_ROW = 3 * 8 + 1


def walk_nbytes(walk: Any) -> int:
    """The bytes a walk's arrays hold, at most: its table's columns, its steps' recorded segments and the CoM
    curve's parts the calibration attaches later (reserved, `HERMITE_BYTES_PER_ROW` a row); the small per-step
    states are not counted."""
    table = getattr(walk, "table", {})
    n = sum(np.asarray(v).nbytes for v in table.values())
    n += HERMITE_BYTES_PER_ROW * len(table.get("t_s", ()))
    for s in getattr(walk, "steps", ()):
        for seg in getattr(s, "segments", None) or ():
            n += seg.t.nbytes + seg.y.nbytes
    return int(n)


class WalkCache:
    """A least-recently-used map key -> walk holding at most ``max_walks`` walks and ``max_bytes`` bytes of their
    arrays (`walk_nbytes` when stored): storing evicts the least recently used until both hold (a single walk
    larger than ``max_bytes`` is not stored). ``hits`` and ``misses`` count `get`'s answers."""

    def __init__(self, max_walks: int = WALK_CACHE_WALKS, max_bytes: int = WALK_CACHE_BYTES) -> None:
        if max_walks < 1 or max_bytes < 1:
            raise ValueError("a walk cache holds at least one walk and one byte")
        self.max_walks = max_walks
        self.max_bytes = max_bytes
        self._walks: OrderedDict[Hashable, tuple[Any, int]] = OrderedDict()
        self.nbytes = 0
        self.hits = 0
        self.misses = 0

    def __len__(self) -> int:
        return len(self._walks)

    def __contains__(self, key: Hashable) -> bool:
        return key in self._walks

    def get(self, key: Hashable) -> Any | None:
        """The walk stored under ``key`` (now the most recently used), or None."""
        got = self._walks.get(key)
        if got is None:
            self.misses += 1
            return None
        self.hits += 1
        self._walks.move_to_end(key)
        return got[0]

    def put(self, key: Hashable, walk: Any) -> None:
        """Store ``walk`` under ``key`` as the most recently used, evicting the least recently used first."""
        size = walk_nbytes(walk)
        old = self._walks.pop(key, None)
        if old is not None:
            self.nbytes -= old[1]
        if size > self.max_bytes:
            return
        while self._walks and (len(self._walks) >= self.max_walks or self.nbytes + size > self.max_bytes):
            _, (_, dropped) = self._walks.popitem(last=False)
            self.nbytes -= dropped
        self._walks[key] = (walk, size)
        self.nbytes += size
