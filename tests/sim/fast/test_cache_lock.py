"""numba's on-disk cache with several processes adding entries to one function's index at once
(rimless.sim.fast.compiling.lock_cache_saves): every entry survives and names its own data."""

from __future__ import annotations

import multiprocessing

from numba.core import caching

from rimless.sim.fast import compiling

WRITERS, ENTRIES = 4, 40


def _writer(folder: str, writer: int, start: object) -> None:
    compiling.lock_cache_saves()  # a spawned process: as importing rimless.sim.fast does
    cache = caching.IndexDataCacheFile(folder, "kernel-1.py311", "stamp")
    start.wait()  # type: ignore[attr-defined]
    for i in range(ENTRIES):
        cache.save(("key", writer, i), ("data", writer, i))


def test_entries_added_by_processes_at_once_all_name_their_own_data(tmp_path):
    """Four processes add 40 entries each to one index, released together. Without the lock, entries go
    missing from the index (a read-modify-write lost) or two keys share one data file (the same free name
    taken twice), so a key loads another key's data."""
    ctx = multiprocessing.get_context("spawn")
    start = ctx.Barrier(WRITERS)
    procs = [ctx.Process(target=_writer, args=(str(tmp_path), w, start)) for w in range(WRITERS)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(timeout=120)
        assert p.exitcode == 0
    cache = caching.IndexDataCacheFile(str(tmp_path), "kernel-1.py311", "stamp")
    for w in range(WRITERS):
        for i in range(ENTRIES):
            assert cache.load(("key", w, i)) == ("data", w, i)


def test_the_lock_is_held_while_an_entry_is_written(tmp_path, monkeypatch):
    import fcntl

    compiling.lock_cache_saves()
    seen = []

    def probe(self, overloads):
        with open(f"{self._index_path}.lock", "a") as other:  # another open file: flock conflicts with it
            try:
                fcntl.flock(other, fcntl.LOCK_EX | fcntl.LOCK_NB)
                seen.append("free")
            except BlockingIOError:
                seen.append("held")

    monkeypatch.setattr(caching.IndexDataCacheFile, "_save_index", probe)
    monkeypatch.setattr(caching.IndexDataCacheFile, "_save_data", lambda self, name, data: None)
    caching.IndexDataCacheFile(str(tmp_path), "kernel-2.py311", "stamp").save("key", "data")
    assert seen == ["held"]
