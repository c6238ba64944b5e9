"""Angle helpers: the single wrap, and quaternion conventions (x, y, z, w; body -> ENU)."""
import numpy as np
from hypothesis import given, strategies as st

from gyro_thermal_comp.angles import (euler_from_quat, quat_from_euler, rotation_matrix_from_quat,
                                      wrap_angle, yaw_from_quat)

finite = st.floats(-1e4, 1e4, allow_nan=False)


@given(finite)
def test_wrap_range_and_equivalence(a):
    w = wrap_angle(a)
    assert -np.pi < w <= np.pi
    assert np.isclose(np.cos(w), np.cos(a), atol=1e-9) and np.isclose(np.sin(w), np.sin(a), atol=1e-9)


def test_wrap_edges_and_arrays():
    assert wrap_angle(np.pi) == np.pi
    assert wrap_angle(-np.pi) == np.pi
    assert np.allclose(wrap_angle(np.array([0.0, 3 * np.pi, -0.5])), [0.0, np.pi, -0.5])


@given(st.floats(-3.1, 3.1), st.floats(-1.5, 1.5), st.floats(-3.1, 3.1))
def test_euler_round_trip(roll, pitch, yaw):
    r, p, y = euler_from_quat(quat_from_euler(roll, pitch, yaw))
    assert np.allclose([r, p, y], [roll, pitch, yaw], atol=1e-9)


def test_yaw_is_ccw_from_east():
    # yaw +90 deg: body x (forward) points north (ENU y)
    q = quat_from_euler(0.0, 0.0, np.pi / 2)
    assert np.allclose(rotation_matrix_from_quat(q) @ [1, 0, 0], [0, 1, 0], atol=1e-12)
    assert np.isclose(yaw_from_quat(q), np.pi / 2)
