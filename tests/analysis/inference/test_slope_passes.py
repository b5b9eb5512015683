"""`calibrate --fit c,k` sizes the trials' slope intervals with the fitted k (issue 31,
`rimless.analysis.api.slope_passes`).

The trials are Vicon exports of the independent truth model `tests.support.analysis_trial_truth` (a compliant ER
wheel with c = 12 N s/m and k = 1800 N/m, not Table 1's 8 and 2700; object origin off the hub, yaw, 0.3 mm and
1 mrad noise), released away from their gait so that their speed changes and the legs' drift counts. A user
fitting k cannot tell the importer k: the first import assumes the importer's bound (45 ms for sqrt(m/k)); the
calibration then imports them again told the fitted k and its standard error. The expected intervals are
the importer's own for a wheel stated with that k (`import_trial(wheel=)`), and the truth's slopes must lie in
them.
"""

from __future__ import annotations

import math
import re

import pytest

from rimless.analysis.api.slope_passes import MAX_SLOPE_PASSES, SLOPE_PASS_RTOL, slope_change

TRUTH_C, TRUTH_K = 12.0, 1800.0
#: (slope deg, release rad/s): one released slow, one fast, each changing speed over its nine steps
CASES = ((2.2, 1.8), (2.8, 2.6))


def _half_deg(trial) -> float:
    lo, hi = trial.meta.slope_ci_rad
    return math.degrees(hi - lo) / 2


def _minima_drift_mm(trial) -> float:
    """The drift of the minima depth the trial's impact line allowed, mm (from its method, in words)."""
    found = re.findall(r"([0-9.]+) mm of drift of the minima depth allowed", trial.meta.slope_method)
    assert found, trial.meta.slope_method
    return float(found[0])


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    import tests.support.analysis_trial_truth as tt
    from rimless.analysis import calibrate
    from rimless.sim import Wheel
    from rimless.sim.model.uncertain import UNCERTAIN_FIELDS

    d = tmp_path_factory.mktemp("kfit")
    paths = []
    for i, (s, w) in enumerate(CASES):
        tr = tt.simulate_wheel(s, w, c_ns_per_m=TRUTH_C, k_n_per_m=TRUTH_K, max_steps=9, ending="walked", seed=i)
        paths.append(tt.write_csv(d / f"er{i}.csv", tr))
    exact = Wheel(uncertainty={f: 0.0 for f in UNCERTAIN_FIELDS})  # Table 1's masses and L0: the truth's
    return paths, calibrate(paths, fit=("c", "k"), wheel=exact)


@pytest.mark.slow
def test_fit_c_k_sizes_the_slope_intervals_with_the_fitted_k(fitted, capsys):
    from rimless.analysis.cli.critical import _print_calibration
    from rimless.analysis.kinematics.build import import_trial
    from rimless.sim import Wheel
    from rimless.sim.model.uncertain import UNCERTAIN_FIELDS

    paths, res = fitted
    passes = res.slope_passes
    assert passes["reimported_with_fitted_k"] and 2 <= passes["passes"] <= MAX_SLOPE_PASSES, passes
    told = passes["legs_k"]  # the k the kept pass's slopes were imported with: a fit's, sd with its held part
    k = next(p for p in res.params if p.name == "k")
    assert k.identifiable or k.effective_only
    lo_told = told["value_n_per_m"] - 1.959963984540054 * told["sd_n_per_m"]
    assert lo_told <= TRUTH_K <= told["value_n_per_m"] + 1.959963984540054 * told["sd_n_per_m"]
    if passes["stable"]:  # the last fit's k moved the slopes by at most SLOPE_PASS_RTOL of a half width
        assert passes["history"][-1]["change"] <= SLOPE_PASS_RTOL
    stated = Wheel(
        stiffness_n_per_m=told["value_n_per_m"],
        uncertainty={**{f: 0.0 for f in UNCERTAIN_FIELDS}, "stiffness_n_per_m": told["sd_n_per_m"]},
    )
    told_k = f"k = {told['value_n_per_m']:.0f} +- {told['sd_n_per_m']:.0f} N/m"  # the importer's words for it
    assert "45 ms" not in passes["legs"] and told_k in passes["legs"], (told_k, passes["legs"])
    for path, trial, (slope, _) in zip(paths, res.trials, CASES):
        as_stated = import_trial(path, wheel=stated)  # the importer told that k by a user
        assert trial.meta.slope_ci_rad == pytest.approx(as_stated.meta.slope_ci_rad, rel=1e-12, abs=0)
        assert trial.meta.slope_deg == pytest.approx(as_stated.meta.slope_deg, rel=1e-12)
        not_told = import_trial(path)  # the first pass's: the importer's bound
        # narrower with the fitted k, unless the estimates that the bound's drift reconciled now disagree and the
        # interval spans both (the 2.8 deg walk, since the truth's wheel stands on its legs before the release:
        # its contact line is 2 standard errors low)
        assert _half_deg(trial) < _half_deg(not_told) or "spans the disagreeing" in trial.meta.slope_method
        assert _minima_drift_mm(trial) < _minima_drift_mm(not_told)  # the drift allowed, either way
        lo, hi = (math.degrees(v) for v in trial.meta.slope_ci_rad)
        assert lo <= slope <= hi, (slope, lo, hi)  # still holds the truth
    # the output says so, in the JSON and the text
    out = res.summary()
    assert out["slope_passes"]["statement"].startswith("the slopes were re-imported with the fitted k")
    assert out["slope_passes"]["passes"] == passes["passes"]
    _print_calibration(out)
    text = " ".join(capsys.readouterr().out.split())
    assert "slopes: the slopes were re-imported with the fitted k" in text
    assert f"{passes['passes']} calibration passes" in text


def test_the_slopes_change_is_the_largest_move_over_a_half_width():
    """By hand: half widths 0.05 -> 0.04 deg (a move of 0.2 of the old) and a slope moved 0.001 deg of a
    0.02 deg half width (0.05): the change is 0.2; a trial without interval on both sides adds nothing, one
    that gains or loses it is an infinite change."""
    row = lambda s, lo, hi: {"slope_deg": s, "ci95_deg": [lo, hi] if lo is not None else None}  # noqa: E731
    before = [row(2.0, 1.95, 2.05), row(3.0, 2.98, 3.02), row(1.0, None, None)]
    after = [row(2.0, 1.96, 2.04), row(3.001, 2.981, 3.021), row(1.0, None, None)]
    assert slope_change(before, after) == pytest.approx(0.2, rel=1e-9)
    assert slope_change(before[1:2], after[1:2]) == pytest.approx(0.05, rel=1e-6)
    assert slope_change(before, before) == 0.0
    assert slope_change(before[2:], [row(1.0, 0.9, 1.1)]) == math.inf


def test_a_wheel_from_a_wheel_input_holds_and_carries_it():
    """`Wheel.from_input`: the input's values (or the ``params`` given), its uncertainties and sources as
    `input`/`uncertainty`, the model asked."""
    from rimless.sim import Wheel
    from rimless.sim.model.uncertain import default_wheel_input

    win = default_wheel_input().with_entry("stiffness_n_per_m", 1900.0, 55.0, "fitted", "by hand")
    w = Wheel.from_input(win, "ve")
    assert w.model == "ve" and w.params.stiffness_n_per_m == 1900.0 and w.input is win
    assert w.uncertainty["stiffness_n_per_m"] == 55.0
    assert w.uncertainty["hub_mass_kg"] == win.entries["hub_mass_kg"].sd
    planned = win.params.replace(damping_ns_per_m=9.5)
    assert Wheel.from_input(win, params=planned).params == planned
