"""The inertia ratio's verdict never contradicts its own figures (issue 31: "the output never contradicts itself";
"a model that does not fit makes its parameters effective only, never identifiable").

Truth: the bundled SYNTHETIC trials' truth files (analysis/data/SYNTHETIC_truth.toml: Table 1's compliant ER
wheel, r = I_hub / (M L0^2) = 0.43, L0 = 237 mm; analysis/data/critical/SYNTHETIC_crit_truth.toml: the same wheel
with c = 10 N s/m and 0.06 N of guide friction), written by rimless.sim and read here from their TOML, and the
rigid truth of tests/support/analysis_rigid_truth.py (a scipy pendulum written apart from the estimator).
On main the six ER trials gave r = 0.02 (at its bound), I_c < 0 and a reduced chi^2 of 42.5 with
``rigid_map_fits: true``; the critical series an L0 of 141.5 mm (true legs 237 mm) with no word that it is
effective.
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from rimless.analysis.inference.stance_inertia import (
    CHI2_ADEQUATE,
    VERDICT_EFFECTIVE,
    VERDICT_FITS,
    VERDICT_NO_FIT,
    VERDICT_NOT_TRIED,
    estimate_inertia_ratio,
    inertia_ratio,
)
from rimless.sim.model.params import WheelParams
from tests.support.analysis_rigid_truth import RigidTruth, duck_trial

Z95 = 1.959963984540054
DATA = Path(__file__).resolve().parents[3] / "analysis" / "data"


def _truth_params(toml: Path) -> WheelParams:
    """The truth's wheel: its [params] table when it has one, else Table 1's (the critical series' file says
    'the ER wheel of rimless.sim' with only c and friction changed, neither of which enters r or L0)."""
    table = tomllib.loads(toml.read_text()).get("params", {})
    keys = ("hub_mass_kg", "leg_mass_kg", "inertia_kg_m2", "leg_length_m", "gravity_m_s2")
    return WheelParams(**{k: float(table[k]) for k in keys if k in table})


def _imported(pattern: str) -> list:
    from rimless.analysis.kinematics.build import import_trial

    return [import_trial(f) for f in sorted(DATA.glob(pattern))]


def _assert_consistent(d: dict) -> None:
    """The JSON's figures and its verdict say one thing."""
    v = d["rigid_map_verdict"]
    assert v in (VERDICT_FITS, VERDICT_EFFECTIVE, VERDICT_NO_FIT, VERDICT_NOT_TRIED) and d["rigid_map_verdict_reason"]
    assert (v == VERDICT_FITS) == (d["rigid_map_fits"] is True)
    assert d["effective_only"] == (v == VERDICT_EFFECTIVE)
    if v == VERDICT_FITS:  # a passed goodness-of-fit test, inside the bounds, a positive inertia
        assert d["estimated"] and d["reduced_chi2_at_held_leg_length"] <= CHI2_ADEQUATE
        assert d["inertia_kg_m2"] > 0 and 0.02 < d["inertia_ratio_at_held_leg_length"] < 50
    if v == VERDICT_EFFECTIVE:
        assert "effective" in d["note"].lower() and d["rigid_map_fits"] is False
    if v in (VERDICT_NO_FIT, VERDICT_NOT_TRIED):
        assert d["inertia_ratio"] is None and d["leg_length_m"] is None and not d["estimated"]
    if d["inertia_kg_m2"] is not None:  # a negative inertia is never a result
        assert d["inertia_kg_m2"] > 0
    for k in ("inertia_ratio", "leg_length_m", "reduced_chi2"):
        assert d[k] is None or math.isfinite(d[k])


def _claims_cover_the_truth(d: dict, truth: WheelParams) -> None:
    """Whatever is claimed as the wheel's (verdict "fits") holds the truth; whatever does not hold it is named
    effective or not estimated."""
    r_true = inertia_ratio(truth)
    if d["rigid_map_verdict"] != VERDICT_FITS:
        return
    assert abs(d["inertia_ratio"] - r_true) <= Z95 * d["inertia_ratio_se"], d
    if d["leg_length_m"] is not None:
        assert abs(d["leg_length_m"] - truth.leg_length_m) <= Z95 * d["leg_length_sd_m"], d


def test_the_bundled_er_trials_at_the_bound_with_chi2_42_do_not_claim_the_map_fits():
    truth = _truth_params(DATA / "SYNTHETIC_truth.toml")
    assert inertia_ratio(truth) == pytest.approx(0.43, abs=0.005)  # the truth file's wheel
    d = estimate_inertia_ratio(_imported("SYNTHETIC_er_*.csv"), WheelParams()).as_dict()
    _assert_consistent(d)
    _claims_cover_the_truth(d, truth)
    assert d["rigid_map_fits"] is False and d["rigid_map_verdict"] != VERDICT_FITS
    assert "at the end of the range searched" in d["rigid_map_verdict_reason"]
    assert d["inertia_kg_m2"] is None and d["inertia_ratio_at_held_leg_length"] is None  # no inertia <= 0, no bound
    if d["leg_length_m"] is not None:  # the joint fit's L0 is far from the truth's legs: labelled effective
        assert d["effective_only"] and "not a measurement of the wheel's legs" in d["rigid_map_verdict_reason"]


def test_the_critical_series_leg_length_is_named_effective():
    truth = _truth_params(DATA / "critical" / "SYNTHETIC_crit_truth.toml")
    d = estimate_inertia_ratio(_imported("critical/*.csv"), WheelParams()).as_dict()
    _assert_consistent(d)
    _claims_cover_the_truth(d, truth)
    # the periods' pendulum is shorter than the legs (a compliant stance): reported, and called effective
    assert d["leg_length_m"] is not None and d["leg_length_m"] + Z95 * d["leg_length_sd_m"] < truth.leg_length_m
    assert d["rigid_map_fits_with_fitted_leg_length"] is True and d["effective_only"] is True
    assert "effective pendulum" in d["note"] and "not a measurement of the wheel's legs" in d["note"]


def test_a_rigid_wheel_that_fits_says_so_and_holds_its_truth():
    """The verdict "fits" is still given where it is true (a rigid truth, r = 1.2, L0 = 250 mm, held at it)."""
    truth = RigidTruth(mass_kg=2.6, inertia_hub_kg_m2=1.2 * 2.6 * 0.25**2, leg_m=0.25)
    rng = np.random.default_rng(2)
    crit = truth.critical_slope_deg()
    trials = [
        duck_trial(truth, round(crit + d, 2), w, rng, name=f"s{d}_{w}", ramp_steps=16)
        for d in (0.15, 0.35, 0.55)
        for w in (1.6, 2.2)
    ]
    d = estimate_inertia_ratio(trials, WheelParams(leg_length_m=0.25)).as_dict()
    _assert_consistent(d)
    assert d["rigid_map_verdict"] == VERDICT_FITS, d["note"]
    assert abs(d["inertia_ratio"] - 1.2) <= Z95 * d["inertia_ratio_se"]


def test_too_few_periods_claim_no_fit():
    truth = RigidTruth(mass_kg=2.0, inertia_hub_kg_m2=3 * 2.0 * 0.237**2)
    trials = [duck_trial(truth, 1.2, 1.6, np.random.default_rng(0), name="short", ramp_steps=4)]  # 2 pairs
    d = estimate_inertia_ratio(trials, WheelParams()).as_dict()
    _assert_consistent(d)
    assert d["rigid_map_verdict"] == VERDICT_NOT_TRIED and d["rigid_map_fits"] is None
