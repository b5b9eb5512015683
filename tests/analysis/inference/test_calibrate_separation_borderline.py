"""The calibration's use of `loss_separation`'s borderline band (session 22, issue 31): the degrees of freedom it
hands over are the trials' count less one when c's standard error is inflated over the model-based one (by the
trial-clustered sandwich or anything else; as `model_choice.dispersion`), else None (the residuals'); a c that stays identifiable on the point rule but lies in
the band carries the note, and one clear of the limit carries none. `loss_separation` itself is replaced by a
recorder (its band is tested in test_loss_separation.py); the objective is a stand-in with no simulation."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from rimless.analysis.inference import calibrate as cal
from rimless.analysis.inference import loss_separation as ls_mod


def _run(monkeypatch, se_model: float, se_sandwich: float, borderline: bool, n_t: int = 6, se: float | None = None):
    seen: dict = {}

    def fake(J, r, offs, n_global, j_c, c_value, infl, v, scale, max_rel_se=0.05, se_dof=None):
        seen.update(se_dof=se_dof, infl=infl)
        note = "speeds: enough (c's relative standard error 4.8% with one free, limit 5.0%)"
        if borderline:
            note += "; a borderline verdict: ..."
        return {"damping_identified": True, "borderline": borderline, "note": note}

    monkeypatch.setattr(ls_mod, "loss_separation", fake)
    walk = SimpleNamespace(table={"t_s": np.linspace(0, 1, 11), "dL1_m_s": np.full(11, 0.2)})
    obj = SimpleNamespace(
        unpack=lambda u: (np.zeros(1), np.full(n_t, 2.0), None),
        glob=SimpleNamespace(params=lambda xg: None),
        data=[SimpleNamespace(slope_deg=2.0, periods_s=np.ones(3), first_angle_offset_rad=0.0)] * n_t,
        sim=SimpleNamespace(walk=lambda *a: walk),
        fun=lambda u: np.zeros(3),
        offs=np.arange(n_t + 1),
        n_g=1,
        n_t=n_t,
    )
    se = max(se_model, se_sandwich) if se is None else se  # NaN-safe: max(x, nan) is x
    e = cal.ParamEstimate("c", "damping_ns_per_m", "N s/m", 8.0, 10.0, se, True)
    e.se_model, e.se_sandwich = se_model, se_sandwich
    cal._check_loss_separation(obj, np.zeros(1), np.zeros((3, 1)), ["c"], np.ones(1), [e])  # type: ignore[arg-type]
    return e, seen


@pytest.mark.parametrize(
    ("se_model", "se_sandwich", "se", "dof"),
    [
        (0.1, 0.3, 0.3, 5),  # the trials' scatter set it
        (0.3, 0.1, 0.3, None),  # the model-based se: the residuals' dof
        (0.3, math.nan, 0.3, None),
        (0.3, 0.1, 0.6, 5),  # inflated by something else (minima spanned, ...): the trials' count too
    ],
)
def test_the_degrees_of_freedom_follow_what_set_the_standard_error(monkeypatch, se_model, se_sandwich, se, dof):
    e, seen = _run(monkeypatch, se_model, se_sandwich, borderline=False, se=se)
    assert seen["se_dof"] == dof
    assert seen["infl"] == pytest.approx(se / se_model)
    assert e.identifiable and e.note == ""  # clear of the limit: no note


def test_a_borderline_identifiable_c_carries_the_note(monkeypatch):
    e, _ = _run(monkeypatch, 0.1, 0.3, borderline=True)
    assert e.identifiable and not e.effective_only  # the point rule decides the verdict
    assert "borderline" in e.note and "limit 5.0%" in e.note
