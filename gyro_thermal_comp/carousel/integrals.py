"""Per-revolution integrals with the rotation done exactly.

In-plane vectors are complex numbers z = x + i*y. A platform-frame vector maps to the carousel frame
as z_c = exp(i*theta) * z_p (v_c = Rz(theta) v_p). Between two samples the platform-frame signal is
modelled as z_p(theta) = b + exp(-i*theta) * w: a constant sensor-fixed part b (bias, lever-arm
centripetal) plus a carousel-fixed part w (body rate, gravity), fitted to the two end samples. The
angle integral of z_c over each segment is then closed-form, so over a whole revolution

    (1/2pi) * integral exp(i*theta) z_p dtheta

cancels a constant platform bias to rounding error (the b terms telescope to b*(E_end - E_start),
and E_end = E_start after exactly 2*pi) and passes a constant carousel-frame vector exactly, however
unevenly the table turns. A plain time average would leak bias whenever the rate wobbles, because
integral cos(theta(t)) dt over a turn is not zero unless theta is linear in t.
"""
from __future__ import annotations

import numpy as np


def inplane(v: np.ndarray) -> np.ndarray:
    """The x, y components of vectors (..., 3) as complex numbers x + i*y."""
    return v[..., 0] + 1j * v[..., 1]


def _segment_weight(d: np.ndarray) -> np.ndarray:
    """f(d) = (d + i(e^{id} - 1)) / (1 - e^{-id}), written to stay accurate for small d.

    Numerator = (d - sin d) - 2i sin^2(d/2); denominator = 2i sin(d/2) e^{-id/2}; f -> -d/2 as d->0."""
    d = np.asarray(d, dtype=float)
    half = 0.5 * d
    small = np.abs(d) < 1e-2
    d_minus_sin = np.where(small, d ** 3 / 6.0 - d ** 5 / 120.0 + d ** 7 / 5040.0, d - np.sin(d))
    num = d_minus_sin - 2j * np.sin(half) ** 2
    den = 2j * np.sin(half) * np.exp(-1j * half)
    with np.errstate(divide='ignore', invalid='ignore'):
        f = num / den
    return np.where(np.abs(d) < 1e-12, -0.5 * d + 0j, f)


def angle_integral(theta: np.ndarray, z: np.ndarray):
    """Integral of exp(i*theta) z dtheta over the polyline (theta_k, z_k), rad * unit(z).
    z: (N,) -> complex, or (N, q) -> (q,) for q signals sampled together."""
    theta = np.asarray(theta, dtype=float)
    z = np.asarray(z, dtype=complex)
    if len(theta) < 2:
        return np.zeros(z.shape[1:], dtype=complex) if z.ndim > 1 else 0j
    ta, tb = theta[:-1], theta[1:]
    d = tb - ta
    ea, eb = np.exp(1j * ta), np.exp(1j * tb)
    w = ea * _segment_weight(d)
    # A segment of (nearly) a whole turn has no unique two-point fit: use the trapezoid there.
    bad = (np.abs(np.sin(0.5 * d)) < 1e-9) & (np.abs(d) > 1.0)
    if z.ndim > 1:
        ea, eb, w, d, bad = ea[:, None], eb[:, None], w[:, None], d[:, None], bad[:, None]
    za, zb = z[:-1], z[1:]
    seg = -1j * za * (eb - ea) + (za - zb) * w
    if np.any(bad):
        seg = np.where(bad, 0.5 * d * (ea * za + eb * zb), seg)
    total = np.sum(seg, axis=0)
    return complex(total) if z.ndim == 1 else total


def interpolate_at_angle(theta_a: float, theta_b: float, z_a: complex, z_b: complex,
                         theta_c: float, frac_t: float) -> complex:
    """Platform-frame in-plane value at angle theta_c inside the segment, with the same two-point
    model b + exp(-i theta) w as `angle_integral`, so splitting a segment there changes nothing.
    Falls back to the time fraction `frac_t` when the segment barely turns."""
    d = theta_b - theta_a
    s = np.sin(0.5 * d)
    if abs(s) < 1e-9:
        rho = frac_t
    else:
        c = theta_c - theta_a
        rho = np.exp(-0.5j * (c - d)) * np.sin(0.5 * c) / s
    return complex(z_a + (z_b - z_a) * rho)


def time_integral(t: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Trapezoid integral over t of samples v (N,) or (N, k), unit(v) * s."""
    t = np.asarray(t, dtype=float)
    v = np.asarray(v)
    if len(t) < 2:
        return np.zeros(v.shape[1:], dtype=v.dtype)
    dt = np.diff(t)
    mid = 0.5 * (v[1:] + v[:-1])
    return np.tensordot(dt, mid, axes=(0, 0))
