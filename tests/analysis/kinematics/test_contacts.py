"""Stance feet from a pose (`rimless.analysis.kinematics.contacts`) on the rigid truth wheel of
`tests.support.analysis_truth_wheel`: without noise the contact points, the slope and the hub come out exact."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rimless.analysis.kinematics.contacts import fit_contacts, hub_from_contacts, slope_from_contacts
from rimless.analysis.kinematics.hub import wheel_angle_from_rotations
from tests.support.analysis_truth_wheel import L, make_truth


@pytest.mark.parametrize("slope_deg, n_steps", [(2.0, 8), (1.3, 2), (0.7, 3)])
def test_exact_feet_slope_and_hub_without_noise(slope_deg, n_steps):
    truth = make_truth(slope_deg=slope_deg, periods_s=(0.45,) * n_steps, ending="walked", end_fraction=0.3)
    origin_body = np.array([0.031, -0.022, 0.0])
    rot = truth.rot.as_matrix()
    trans = truth.hub_world + truth.rot.apply(origin_body)
    angle, axis = wheel_angle_from_rotations(rot)
    fit = fit_contacts(rot, trans, angle, axis, truth.walking)
    assert fit is not None and len(fit.contacts) == n_steps
    # every contact lies on the slope plane through the first foot, one step (2 L sin(alpha/2)) apart
    c = np.array([k.c_m for k in fit.contacts])
    gaps = np.linalg.norm(
        np.diff(c, axis=0) - (np.diff(c, axis=0) @ truth.axis_world)[:, None] * truth.axis_world, axis=1
    )
    np.testing.assert_allclose(gaps, 2 * L * math.sin(math.pi / 8), atol=1e-6)
    np.testing.assert_allclose((c - c[0]) @ truth.normal_world, 0.0, atol=1e-6)
    travel = np.array([truth.down_world[0], truth.down_world[1], 0.0])
    travel /= np.linalg.norm(travel)
    phi, se, rms = slope_from_contacts(fit.contacts, travel)
    assert math.degrees(phi) == pytest.approx(slope_deg, abs=1e-5)
    d, d_se, feet_rms = hub_from_contacts(fit)
    np.testing.assert_allclose(d[:2], -origin_body[:2], atol=2e-5)  # the prior's pull is below 0.02 mm
    assert feet_rms < 1e-5


def test_under_half_a_step_gives_nothing():
    truth = make_truth(slope_deg=2.0, periods_s=(0.45, 0.45), ending="walked")
    rot = truth.rot.as_matrix()
    angle, axis = wheel_angle_from_rotations(rot)
    walking = (truth.time_s >= truth.release_s) & (truth.time_s < truth.release_s + 0.1)  # about 0.2 of a step
    assert fit_contacts(rot, truth.hub_world, angle, axis, walking) is None
