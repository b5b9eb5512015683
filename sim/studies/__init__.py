"""Studies built on the simulator: the work behind the commands, parameter sweeps, the paper's figures,
stress tests, benchmarks.

`gaits` (fixed point, every gait at a slope, critical slope), `walk` (N steps, written and plotted) and
`summary` (their plain-dict form, what `--json` emits); `sweep` (Dask, cached), `paper` and `paper_figures`
(every figure of the paper's simulation section with its CSV), `stress` (every grid point valid or
classified), `figures` (matplotlib: compute first, plot second), `bench` and `sweepbench` (the fast path and
a reference side by side in one run). A study takes plain values and a progress callback and returns plain
data; it never prints.

May import: rimless.sim.model, integrate, fast, step, continuation (never in_the_loop/ or cli/);
rimless.errors, rimless.output, rimless.values; numpy, scipy, pandas, matplotlib, dask.
"""
