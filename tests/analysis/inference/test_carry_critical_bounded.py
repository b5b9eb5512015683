"""The models' critical slopes carry a held F_c at its bound as the calibration does (issue 31, "What is held, is
carried"): F_c = 0 +- 0.2 N can only be above 0, so its part is the stated normal truncated at 0, not +-1 sd about
0 (`rimless.analysis.inference.held.carry_critical`, `carry_rows`).

The model's critical slope is replaced by a closed form linear in F_c and c, so the carried shift and sd are
known exactly: F_c's part has the half-normal's mean 0.2 sqrt(2/pi) and sd 0.2 sqrt(1 - 2/pi) times its slope,
and c (+-50 %: its normal truncated at 0 moves its mean by 0.055 sd) is scipy's truncnorm. Checked also against sampling the truncated normal
(numpy, independent of the closed forms) and, near the bound, against scipy's truncnorm."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from rimless.analysis.inference import held
from rimless.analysis.inference.critical_slope import Z95
from rimless.sim.model.params import WheelParams
from rimless.sim.model.uncertain import wheel_input_from

BASE_DEG = 2.5
PER_N = 0.8  # deg per N of guide friction
PER_C = 0.01  # deg per N s/m of damping


def _carry(monkeypatch: pytest.MonkeyPatch, friction_n: float, central: bool = True) -> dict:
    c0 = WheelParams().damping_ns_per_m

    def critical(p: WheelParams) -> float:  # the closed form standing in for the model's critical slope
        return BASE_DEG + PER_N * p.guide_friction_n + PER_C * (p.damping_ns_per_m - c0)

    monkeypatch.setattr(held, "_model_at", lambda model: critical)
    win = wheel_input_from(WheelParams(guide_friction_n=friction_n), {"F_c": 0.2})
    base = critical(win.params)
    res = SimpleNamespace(chosen=None, model={"critical_slope_deg": {"er": base}})
    out = held.carry_critical(
        res, [], [], win, models=("er",), warm=False, estimate_inertia=False, central_models=central
    )
    e = win.entries["damping_ns_per_m"]
    return out["models"]["er"] | {"c": e.value, "sd_c": e.sd, "base": base}


def _c_part(d: dict) -> tuple[float, float]:
    """c's mean shift and sd (deg): its stated normal truncated at 0 (scipy, independent of the closed forms)."""
    from scipy.stats import truncnorm

    t = truncnorm(-d["c"] / d["sd_c"], np.inf, loc=d["c"], scale=d["sd_c"])
    return PER_C * (t.mean() - d["c"]), PER_C * t.std()


@pytest.mark.parametrize("central", [True, False])
def test_friction_at_zero_is_carried_as_the_half_normal(monkeypatch: pytest.MonkeyPatch, central: bool) -> None:
    d = _carry(monkeypatch, 0.0, central)
    shift = PER_N * 0.2 * math.sqrt(2.0 / math.pi)
    sd_f = PER_N * 0.2 * math.sqrt(1.0 - 2.0 / math.pi)
    shift_c, sd_c = _c_part(d)
    se = math.hypot(sd_f, sd_c)
    assert d["critical_slope_deg"] == pytest.approx(BASE_DEG)  # the value at the held values keeps its meaning
    assert d["held_shift_deg"] == pytest.approx(shift + shift_c, rel=1e-6)
    shift += shift_c
    assert d["critical_slope_with_held_deg"] == pytest.approx(BASE_DEG + shift, rel=1e-9)
    assert d["se_parameters_deg"] == pytest.approx(se, rel=1e-6)
    assert d["ci_deg"] == pytest.approx([BASE_DEG + shift - Z95 * se, BASE_DEG + shift + Z95 * se], rel=1e-6)
    by = {r["symbol"]: r for r in d["contributions"]}
    assert by["F_c"]["shift_deg"] == pytest.approx(shift - shift_c, rel=1e-6)
    assert "truncated at its bound 0" in by["F_c"]["carried_as"]
    assert by["c"]["shift_deg"] == pytest.approx(shift_c, rel=1e-6)
    assert by["c"]["contribution_deg"] == pytest.approx(sd_c, rel=1e-6)


def test_the_carried_interval_matches_sampling(monkeypatch: pytest.MonkeyPatch) -> None:
    """The critical slope at wheels drawn from the stated uncertainties (F_c's normal truncated at 0 by
    rejection, c's too): its mean and sd are the carried centre and se."""
    d = _carry(monkeypatch, 0.0)
    rng = np.random.default_rng(7)
    f = rng.normal(0.0, 0.2, 800_000)
    f = f[f >= 0.0][:300_000]
    c = rng.normal(d["c"], d["sd_c"], 2 * f.size)
    c = c[c >= 0.0][: f.size]
    slope = d["base"] + PER_N * f + PER_C * (c - d["c"])
    assert d["critical_slope_with_held_deg"] == pytest.approx(slope.mean(), abs=4 * slope.std() / math.sqrt(f.size))
    assert d["se_parameters_deg"] == pytest.approx(slope.std(), rel=0.01)


def test_friction_near_its_bound_matches_scipys_truncated_normal(monkeypatch: pytest.MonkeyPatch) -> None:
    """F_c = 0.1 +- 0.2 N: -1 sd is not a wheel, the +1 sd change carried by the normal truncated at 0."""
    from scipy.stats import truncnorm

    d = _carry(monkeypatch, 0.1)
    t = truncnorm(-0.5, np.inf, loc=0.1, scale=0.2)
    by = {r["symbol"]: r for r in d["contributions"]}
    assert by["F_c"]["shift_deg"] == pytest.approx(PER_N * (t.mean() - 0.1), rel=1e-6)
    assert by["F_c"]["contribution_deg"] == pytest.approx(PER_N * t.std(), rel=1e-6)


def test_parameters_say_how_each_is_carried() -> None:
    """The ``parameters`` entries name the truncation exactly where `carry_bounded` applies it: F_c = 0 +- 0.2 N
    and c +- 50 % (0.055 sd) truncated at 0, m_H +- 2 % a plain normal, g exact, a fitted value fitted."""
    win = wheel_input_from(WheelParams(), {"F_c": 0.2})
    rows = {r["symbol"]: r for r in win.parameters()}
    assert rows["F_c"]["carried_as"] == "normal truncated at 0"
    assert rows["c"]["carried_as"] == "normal truncated at 0"
    assert rows["m_H"]["carried_as"] == "normal" and rows["g"]["carried_as"] == "exact"
    for e in win.held():
        how = held.carry_bounded(e.value, e.sd, 1.0, None)[2]
        assert ("truncated" in how) == (e.carried_as == "normal truncated at 0"), (e.name, how)
    fitted = win.with_entry("damping_ns_per_m", 5.0, 0.3, "fitted", "fitted to the trials")
    assert {r["symbol"]: r for r in fitted.parameters()}["c"]["carried_as"] == "fitted"


def test_the_floquet_models_eigenvalue_is_carried_the_same_way(monkeypatch: pytest.MonkeyPatch) -> None:
    """`trials floquet`'s model eigenvalue: F_c = 0 +- 0.2 N as the half-normal, the interval centred there."""
    from rimless.analysis.inference import floquet

    per_n = -0.3  # eigenvalue per N of guide friction (a closed form standing in for the model's map)
    monkeypatch.setattr(floquet, "model_multiplier", lambda p, model: {"eigenvalue": 0.7 + per_n * p.guide_friction_n})
    win = wheel_input_from(WheelParams(), {"F_c": 0.2, "m_H": 0, "m": 0, "I_c": 0, "L0": 0, "k": 0, "c": 0})
    m = floquet._model_with_uncertainty(win, "er", 2.0, 0.0)
    shift = per_n * 0.2 * math.sqrt(2.0 / math.pi)
    se = abs(per_n) * 0.2 * math.sqrt(1.0 - 2.0 / math.pi)
    assert m["eigenvalue"] == pytest.approx(0.7)
    assert m["held_shift"] == pytest.approx(shift, rel=1e-9) and m["se_parameters"] == pytest.approx(se, rel=1e-9)
    assert m["ci95"] == pytest.approx([0.7 + shift - Z95 * se, 0.7 + shift + Z95 * se], rel=1e-9)
