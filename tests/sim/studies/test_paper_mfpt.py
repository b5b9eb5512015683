"""`rimless paper`'s metastability (issue 33): MFPT against the terrain's roughness S for the three wheels and ER
against VE per k, checked against expectations written here apart from the code:

- the rigid wheel by a Monte Carlo of its closed-form map (below; Table 1 values, paper convention M = m_H,
  inertia I_c about the hub): over a stance w^2 + 2 C cos(theta + phi) is constant (C = M g L / (I_c + M L^2)),
  every step starts at theta = -alpha/2 and ends at alpha/2, the impact gives w+ = beta w-; a step fails by a
  stall (the hub does not pass over the top) or by lift-off (M g cos(theta + phi) < M L w^2 at an end of the
  stance). On a slope of 0.065 rad (3.72 deg, away from Table 1's 2.865) its MFPT is 20-100 steps at S = 1-1.5 deg;
- every wheel's MFPT falls as S grows (the compliant wheels on a coarse mesh: the trend, not the digits);
- the files and their keys, never NaN.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest

from rimless.sim.model.params import WheelParams
from rimless.sim.studies.paper_mfpt import CHEAP_MESH, Mesh, metastability_paper, wheel_mfpt

M, I_C, L, G = 1.892, 0.036, 0.237, 9.81  # Table 1: m_H, I_c, L0, g
ALPHA = math.pi / 4
C = M * G * L / (I_C + M * L * L)
BETA = (I_C + M * L * L * math.cos(ALPHA)) / (I_C + M * L * L)
LIMIT = ALPHA / 2 - 0.01  # slopes beyond are taken at the limit, as the library states (mass < 1e-30 here)


def rigid_monte_carlo(slope: float, sd_deg: float, walks: int = 20000, cap: int = 50000, seed: int = 7):
    """(mean steps before the first failing step, its standard error) of walks from the rigid gait."""
    rng = np.random.default_rng(seed)
    gain = 2 * C * (math.cos(-ALPHA / 2 + slope) - math.cos(ALPHA / 2 + slope))
    w = np.full(walks, math.sqrt(BETA**2 * gain / (1 - BETA**2)))
    alive = np.ones(walks, bool)
    steps = np.zeros(walks)
    for _ in range(cap):
        phi = np.clip(rng.normal(slope, math.radians(sd_deg), walks), -LIMIT, LIMIT)
        e = w * w + 2 * C * np.cos(-ALPHA / 2 + phi)
        lowest = np.minimum(np.cos(-ALPHA / 2 + phi), np.cos(ALPHA / 2 + phi))
        ok = (e >= 2 * C) & (e <= (2 * C + G / L) * lowest)
        alive &= ok
        steps += alive
        if not alive.any():
            break
        w = np.where(alive, BETA * np.sqrt(np.maximum(e - 2 * C * np.cos(ALPHA / 2 + phi), 0.0)), w)
    assert not alive.any(), "a walk reached the cap"
    return steps.mean(), steps.std(ddof=1) / math.sqrt(walks)


def test_table_1_is_the_wheel_of_the_truth_above():
    p = WheelParams()
    assert (p.hub_mass_kg, p.inertia_kg_m2, p.leg_length_m, p.gravity_m_s2) == (M, I_C, L, G)


@pytest.mark.parametrize("sd_deg", [1.0, 1.5])
def test_rigid_wheel_mesh_mfpt_matches_a_monte_carlo_of_its_closed_form(sd_deg):
    params = WheelParams(slope_rad=0.065)
    res = wheel_mfpt(params, "rigid", sd_deg, Mesh(1, 300, 60), backend="auto", rtol=1e-10)
    mc, se = rigid_monte_carlo(0.065, sd_deg)
    assert 20 < mc < 2000
    assert abs(res["mfpt_steps"] - mc) <= 1.96 * se + res["mfpt_discretisation_error_steps"], (res["mfpt_steps"], mc)


def test_rigid_wheel_mfpt_falls_as_the_terrain_gets_rougher():
    params = WheelParams(slope_rad=0.065)
    values = [wheel_mfpt(params, "rigid", s, Mesh(1, 200, 48), backend="auto", rtol=1e-10) for s in (1.0, 1.5, 2.0)]
    mfpt = [v["mfpt_steps"] for v in values]
    assert mfpt[0] > mfpt[1] > mfpt[2] > 1


@pytest.mark.slow
def test_paper_metastability_files_keys_and_the_trend_with_roughness(tmp_path):
    """The three wheels at Table 1 on a coarse mesh (CHEAP_MESH: seconds; its error is reported, and large)."""
    out = metastability_paper(tmp_path, WheelParams(), (2700.0,), mesh=CHEAP_MESH, sds_deg=(0.5, 1.0, 2.0))
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["fig_mfpt.csv", "fig_mfpt.png", "mfpt.json", "mfpt_per_k.csv", "mfpt_terrain.csv"]
    terrain = pd.read_csv(tmp_path / "mfpt_terrain.csv")
    for key in ("wheel", "k_n_per_m", "slope_deg", "terrain_sd_deg", "mfpt_steps", "mfpt_discretisation_error_steps"):
        assert key in terrain.columns
    assert sorted(set(terrain.wheel)) == ["er", "rigid", "ve"]
    for wheel in ("er", "ve"):
        rows = terrain[terrain.wheel == wheel].sort_values("terrain_sd_deg")
        assert list(rows.terrain_sd_deg) == [0.5, 1.0, 2.0]
        assert np.all(np.diff(rows.mfpt_steps.to_numpy()) < 0), rows.mfpt_steps.tolist()
    # Table 1's slope is 0.066 deg above the rigid wheel's critical slope (2.799 deg): it fails within a few
    # steps on any terrain; the independent Monte Carlo says how many
    rigid = terrain[terrain.wheel == "rigid"].set_index("terrain_sd_deg")
    for sd in (0.5, 2.0):
        mc, se = rigid_monte_carlo(WheelParams().slope_rad, sd, walks=4000)
        assert mc < 5 and rigid.mfpt_steps[sd] == pytest.approx(
            mc, abs=4 * se + rigid.mfpt_discretisation_error_steps[sd]
        )
    per_k = pd.read_csv(tmp_path / "mfpt_per_k.csv")
    assert sorted(per_k.wheel) == ["er", "ve"] and set(per_k.k_n_per_m) == {2700.0}
    assert set(per_k.terrain_sd_deg) == {2.0}
    # the (ER, k, S = 2 deg) of both tables is one computation
    er_2 = terrain[(terrain.wheel == "er") & (terrain.terrain_sd_deg == 2.0)].mfpt_steps.iloc[0]
    assert per_k[per_k.wheel == "er"].mfpt_steps.iloc[0] == er_2
    data = json.loads((tmp_path / "mfpt.json").read_text(), parse_constant=lambda c: pytest.fail(f"{c} in JSON"))
    assert data["mesh"] == {"nodes_theta": 3, "nodes_theta_dot": 10, "slopes": 8}
    assert data["terrain"] == out["terrain"]
