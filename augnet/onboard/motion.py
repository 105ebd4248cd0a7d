"""The rover's position-velocity-acceleration motion model: the Kalman prediction over a time step with
white jerk (continuous white noise on the acceleration's derivative)."""

from __future__ import annotations

import numpy as np

from augnet.onboard.spp import receiver_frame


def predict_pva(x: np.ndarray, P: np.ndarray, dt: float, accel_sigma_h: float, accel_sigma_v: float) -> None:
    """Predict x[:9] = (position, velocity, acceleration) ECEF and its covariance (the whole of P, whose
    other states are constant) over dt [s], in place.  accel_sigma_h, accel_sigma_v: horizontal and
    vertical white-jerk noise [m/s^2 / sqrt(s)] in the local ENU frame at the predicted position."""
    F = np.eye(9)
    F[0:3, 3:6] = np.eye(3) * dt
    F[0:3, 6:9] = np.eye(3) * 0.5 * dt * dt
    F[3:6, 6:9] = np.eye(3) * dt
    x[:9] = F @ x[:9]
    Pk = P[:9, :9]
    Pka = P[:9, 9:]
    P[:9, :9] = F @ Pk @ F.T
    P[:9, 9:] = F @ Pka
    P[9:, :9] = P[:9, 9:].T
    # white-jerk noise on acceleration, in local ENU then rotated to ECEF
    _, R = receiver_frame(x[:3])
    q = R.T @ np.diag([accel_sigma_h**2, accel_sigma_h**2, accel_sigma_v**2]) @ R
    # continuous white jerk integrated over dt: the exact discrete Q of the PVA model
    P[6:9, 6:9] += q * dt
    P[3:6, 3:6] += q * dt**3 / 3.0
    P[0:3, 0:3] += q * dt**5 / 20.0
    P[3:6, 6:9] += q * dt**2 / 2.0
    P[6:9, 3:6] += q * dt**2 / 2.0
    P[0:3, 6:9] += q * dt**3 / 6.0
    P[6:9, 0:3] += q * dt**3 / 6.0
    P[0:3, 3:6] += q * dt**4 / 8.0
    P[3:6, 0:3] += q * dt**4 / 8.0
