"""The benchmark's 1 mg double-support rows (rimless.sim.studies.stiffbench.double_support_rows) run and say what
they should: the compiled phase and scipy's DOP853 on the reference model side by side, the compiled one as close
to the rtol 1e-12 reference as scipy's at the same rtol (both are DOP853 on the same equations; measured 3e-12 s
each at rtol 1e-10), the map near the light-leg limit and its Jacobian near central differences. No timing is
asserted (the ratio is printed, never tested)."""

from __future__ import annotations

import math

from rimless.sim.studies.stiffbench import double_support_rows, format_table, light_wheel


def test_double_support_rows_put_the_compiled_phase_beside_scipy() -> None:
    (row,) = double_support_rows((1e-10,), repeats=1)
    (t_fast, y_fast), (t_scipy, y_scipy) = row["fast_errors"], row["scipy_errors"]
    assert t_fast < 1e-10 and y_fast < 1e-9
    assert t_scipy < 1e-10 and y_scipy < 1e-9
    assert row["fast_nfev"] < 500
    assert row["map_limit_error"] < 1e-9  # the rtol 1e-10 map against the limit line of rtol 1e-12 maps
    assert row["map_jacobian_error"] < 1e-6
    assert math.isfinite(row["cpu_ratio"]) and row["cpu_ratio"] > 0
    text = format_table(
        {
            "params": light_wheel(),
            "leg_rate_per_s": 8e4,
            "n_steps": 0,
            "rows": [],
            "friction_rows": [],
            "double_support_rows": [row],
            "load_before": 0.0,
            "load_after": 0.0,
        }
    )
    assert "scipy's DOP853 on the reference model" in text
