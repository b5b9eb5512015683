"""Hub and wheel angle from rotations."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rimless.analysis.kinematics import hub


def test_rotation_stack_matches_the_matrix_array():
    """An object's rotations kept as angles (matrices made slice by slice) give what the (n, 3, 3) array gives."""
    rng = np.random.default_rng(4)
    n = 3000
    angles = np.cumsum(rng.normal(0.0, 0.05, (n, 3)), axis=0)
    angles[rng.random(n) < 0.05] = np.nan
    invalid = rng.random(n) < 0.03
    mats = Rotation.from_rotvec(np.nan_to_num(angles)).as_matrix()
    mats[np.isnan(angles).any(axis=1) | invalid] = np.nan
    stack = hub.RotationStack(angles, "helical", invalid)
    stack.SLICE = 256  # several slices
    np.testing.assert_array_equal(stack[:], mats)
    np.testing.assert_array_equal(stack[[5, 2, 7]], mats[[5, 2, 7]])
    np.testing.assert_array_equal(stack[11], mats[11])
    np.testing.assert_array_equal(stack.valid(), ~np.isnan(mats[:, 0, 0]))
    d, axis = np.array([0.01, -0.02, 0.03]), np.array([0.0, 1.0, 0.0])
    np.testing.assert_allclose(hub.apply_rotations(stack, d), np.einsum("nij,j->ni", mats, d), rtol=0, atol=1e-15)
    np.testing.assert_allclose(hub.axis_in_body(stack, axis), axis @ mats, rtol=0, atol=1e-15)
    a1, x1 = hub.wheel_angle_from_rotations(stack)
    a2, x2 = hub.wheel_angle_from_rotations(mats)
    np.testing.assert_array_equal(a1, a2)
    np.testing.assert_array_equal(x1, x2)
    mask = rng.random(n) < 0.8
    np.testing.assert_array_equal(stack.masked(mask).valid(), stack.valid() & mask)
    with pytest.raises(ValueError):
        hub.RotationStack(angles, "not-a-sequence")
