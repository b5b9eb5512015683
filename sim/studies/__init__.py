"""Studies built on the simulator: parameter sweeps, the paper's figures, stress tests, benchmarks.

`sweep` (Dask, cached), `paper` (every figure of the paper's simulation section with its CSV), `stress`
(every grid point valid or classified), `figures` (matplotlib: compute first, plot second), `bench` and
`sweepbench` (the fast path and a reference side by side in one run).

May import: every sim/ folder except cli/; rimless.output, rimless.progress; numpy, scipy, pandas,
matplotlib, dask.
"""
