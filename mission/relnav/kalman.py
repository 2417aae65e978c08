"""The linear Kalman filter's steps for the relative state (pure numpy, shape ``(9,)`` / ``(9, 9)``).

State ``x = (c, w, b)``: ``c`` (3,) the carrier's reference point in the passenger's GNSS frame
[m] NED, ``w`` (3,) its velocity [m/s], ``b`` (3,) the carrier's GNSS frame minus the
passenger's [m]. The vehicle's own position and velocity are inputs, not states (its autopilot
reports them every tick), so the vehicle's own manoeuvres never enter the model; the relative
position is ``c`` less the vehicle's own. Model, per axis (the axes are independent and identical):

- ``c`` and ``w``: constant velocity driven by a white acceleration of the carrier of spectral
  density ``q = accel_noise^2`` [m^2/s^3];
- ``b``: first-order Gauss-Markov, ``db/dt = -b / tau + w``, stationary standard deviation
  ``sigma_b`` [m] (its own per axis), so ``b(t+dt) = exp(-dt/tau) b(t) + n`` with ``var n = sigma_b^2 (1 - exp(-2 dt/tau))``.

Measurements: the marker plus the vehicle's own position sees ``c``; the carrier's GNSS position
sees ``c + b``; its GNSS velocity sees ``w``. PX4's vision target estimator keeps the same three
parts per axis (a position, a velocity, the GNSS bias; docs/relnav.md).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

N = 9  # state size
C_, W_, B_ = slice(0, 3), slice(3, 6), slice(6, 9)  # the parts of the state: carrier position, velocity, bias
I3 = np.eye(3)
Z3 = np.zeros((3, 3))
H_MARKER = np.hstack([I3, Z3, Z3])  # the marker plus the vehicle's own position sees c
H_GNSS_POSITION = np.hstack([I3, Z3, I3])  # the carrier's GNSS position sees c + b
H_GNSS_VELOCITY = np.hstack([Z3, I3, Z3])  # its GNSS velocity sees w


def transition(dt_s: float, bias_tau_s: float) -> np.ndarray:
    """The (9, 9) transition over ``dt_s`` [s]."""
    f = np.eye(N)
    f[C_, W_] = I3 * dt_s
    f[B_, B_] = I3 * math.exp(-dt_s / bias_tau_s)
    return f


def process_noise(dt_s: float, accel_noise_m_s2: float, bias_sigma_m: np.ndarray, bias_tau_s: float) -> np.ndarray:
    """The (9, 9) process noise accumulated over ``dt_s`` [s] (see the module docstring);
    ``bias_sigma_m`` (3,) the bias's stationary standard deviation per NED axis [m]."""
    q = accel_noise_m_s2 ** 2
    out = np.zeros((N, N))
    out[C_, C_] = I3 * (q * dt_s ** 3 / 3.0)
    out[C_, W_] = out[W_, C_] = I3 * (q * dt_s ** 2 / 2.0)
    out[W_, W_] = I3 * (q * dt_s)
    out[B_, B_] = np.diag(np.asarray(bias_sigma_m, dtype=float) ** 2 * -math.expm1(-2.0 * dt_s / bias_tau_s))
    return out


def predict(x: np.ndarray, p: np.ndarray, f: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The state and covariance moved on by transition ``f`` with process noise ``q``."""
    return f @ x, f @ p @ f.T + q


@dataclass(frozen=True)
class Update:
    """One measurement's update: the new state and covariance (the old ones when rejected), its
    normalised innovation squared ``nis`` [-] and whether the gate let it through."""

    x: np.ndarray
    p: np.ndarray
    nis: float
    accepted: bool


def update(x: np.ndarray, p: np.ndarray, z: np.ndarray, h: np.ndarray, r: np.ndarray, gate_nis: float) -> Update:
    """Fuse measurement ``z`` (m,) of ``h @ x`` with noise covariance ``r`` (m, m), unless its
    normalised innovation squared exceeds ``gate_nis`` (Joseph form, symmetric result)."""
    innovation = z - h @ x
    s = h @ p @ h.T + r
    s_inv = np.linalg.inv(s)
    nis = float(innovation @ s_inv @ innovation)
    if not nis <= gate_nis:  # NaN is rejected too
        return Update(x, p, nis, False)
    k = p @ h.T @ s_inv
    a = np.eye(N) - k @ h
    p_new = a @ p @ a.T + k @ r @ k.T
    return Update(x + k @ innovation, 0.5 * (p_new + p_new.T), nis, True)
