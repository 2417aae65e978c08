"""The linear Kalman filter's steps for the relative state (pure numpy, shape ``(12,)`` / ``(12, 12)``).

State ``x = (c, w, b, d)``: ``c`` (3,) the carrier's reference point in the passenger's GNSS frame
[m] NED, ``w`` (3,) the carrier's velocity [m/s] (its own, as its GNSS measures it), ``b`` (3,)
the carrier's GNSS frame minus the passenger's [m], ``d`` (3,) the rate at which the passenger's
own position estimate drifts [m/s] (its autopilot's estimate error changing: the passenger's frame
moves under the carrier, so in that frame the carrier moves at ``w + d``). The vehicle's own
position and velocity are inputs, not states (its autopilot reports them every tick), so the
vehicle's own manoeuvres never enter the model; the relative position is ``c`` less the vehicle's
own. Model, per axis (the axes independent):

- ``c`` and ``w``: ``dc/dt = w + d``, ``dw/dt = u + n``: ``u`` the acceleration the carrier
  measured and sent (a known input, :func:`input_step`; zero when it sends none: ``w`` a constant
  velocity), ``n`` a white acceleration of spectral density ``q = accel_noise^2`` [m^2/s^3]
  (down: times the vertical factor squared);
- ``b``: first-order Gauss-Markov, ``db/dt = -b / tau - d + n``, stationary standard deviation
  ``sigma_b`` [m] (its own per axis), so ``b(t+dt) = exp(-dt/tau) b(t) - (d's integral) + n``
  with ``var n = sigma_b^2 (1 - exp(-2 dt/tau))`` (the passenger's frame drifting moves ``c`` by
  ``d`` and ``b`` by ``-d``: the carrier's GNSS position ``c + b`` does not move with it);
- ``d``: first-order Gauss-Markov, standard deviation ``sigma_d`` [m/s] per axis, correlation time
  ``tau_d`` [s] (``sigma_d`` 0: no drift, ``d`` stays 0 and the filter is the nine-state one).

Measurements: the marker plus the vehicle's own position sees ``c``; the carrier's GNSS position
sees ``c + b``; its GNSS velocity sees ``w``. With the marker the filter learns ``d`` (the
marker's rate of ``c`` against the GNSS velocity), and through a marker loss the deck keeps
moving in the passenger's frame with the drift it learnt, fading over ``tau_d``, instead of the
GNSS velocity pulling the deck's velocity to the carrier's within a few fixes. PX4's vision
target estimator keeps the first three parts per axis (docs/relnav.md).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

N = 12  # state size
# the parts of the state: carrier position, velocity, bias, the passenger's own drift rate
C_, W_, B_, D_ = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12)
I3 = np.eye(3)
Z3 = np.zeros((3, 3))
H_MARKER = np.hstack([I3, Z3, Z3, Z3])  # the marker plus the vehicle's own position sees c
H_GNSS_POSITION = np.hstack([I3, Z3, I3, Z3])  # the carrier's GNSS position sees c + b
H_GNSS_VELOCITY = np.hstack([Z3, I3, Z3, Z3])  # its GNSS velocity sees w


def transition(dt_s: float, bias_tau_s: float, drift_tau_s: float) -> np.ndarray:
    """The (12, 12) transition over ``dt_s`` [s] (``dt_s`` much shorter than ``bias_tau_s``)."""
    f = np.eye(N)
    f[C_, W_] = I3 * dt_s
    f[B_, B_] = I3 * math.exp(-dt_s / bias_tau_s)
    f[D_, D_] = I3 * math.exp(-dt_s / drift_tau_s)
    drift = I3 * (drift_tau_s * -math.expm1(-dt_s / drift_tau_s))  # d's integral over dt, per unit of d
    f[C_, D_] = drift
    f[B_, D_] = -drift
    return f


def process_noise(dt_s: float, accel_noise_m_s2: np.ndarray, bias_sigma_m: np.ndarray, bias_tau_s: float,
                  drift_sigma_m_s: np.ndarray, drift_tau_s: float) -> np.ndarray:
    """The (12, 12) process noise accumulated over ``dt_s`` [s] (see the module docstring);
    ``accel_noise_m_s2`` (3,) the carrier's acceleration noise per NED axis [m/s^2/sqrt(Hz)],
    ``bias_sigma_m`` (3,) the bias's stationary standard deviation per NED axis [m],
    ``drift_sigma_m_s`` (3,) the drift rate's [m/s]."""
    q = np.diag(np.asarray(accel_noise_m_s2, dtype=float) ** 2)
    out = np.zeros((N, N))
    out[C_, C_] = q * (dt_s ** 3 / 3.0)
    out[C_, W_] = out[W_, C_] = q * (dt_s ** 2 / 2.0)
    out[W_, W_] = q * dt_s
    out[B_, B_] = np.diag(np.asarray(bias_sigma_m, dtype=float) ** 2 * -math.expm1(-2.0 * dt_s / bias_tau_s))
    out[D_, D_] = np.diag(np.asarray(drift_sigma_m_s, dtype=float) ** 2 * -math.expm1(-2.0 * dt_s / drift_tau_s))
    return out


def input_step(dt_s: float, accel_ned_m_s2: np.ndarray) -> np.ndarray:
    """The (12,) change of the state over ``dt_s`` [s] that the carrier's known acceleration
    ``accel_ned_m_s2`` (3,) [m/s^2], held over the step, makes: ``c`` by ``u dt^2 / 2``, ``w`` by ``u dt``."""
    u = np.asarray(accel_ned_m_s2, dtype=float)
    out = np.zeros(N)
    out[C_] = 0.5 * dt_s * dt_s * u
    out[W_] = dt_s * u
    return out


def predict(x: np.ndarray, p: np.ndarray, f: np.ndarray, q: np.ndarray,
            step: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The state and covariance moved on by transition ``f`` with process noise ``q``, plus a
    known input's change ``step`` (:func:`input_step`; None: no input)."""
    x_new = f @ x if step is None else f @ x + step
    return x_new, f @ p @ f.T + q


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
