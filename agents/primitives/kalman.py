"""Constant-velocity Kalman filter for box tracks (the motion cue of association).

DeepSORT's filter (Wojke et al., ICIP 2017), as in JDE and UniTrack (appendix C.1): state
``(u, v, a, h, du, dv, da, dh)`` (centre, aspect ``w / h``, height and their per-frame
velocities); measurements ``(u, v, a, h)``. The paper's text writes ``gamma = h / w``, but the
filter it cites and the authors' code use ``w / h``, for which the aspect's absolute noise
levels are calibrated, so ``w / h`` it is. Position and velocity stds are proportional to the
box height (1/20, 1/160), the aspect's are fixed (:class:`KalmanConfig`). Every method is
batched over tracks (``mean`` ``(n, 8)``, ``covariance`` ``(n, 8, 8)``), in float64.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

STATE_DIM = 8
"""Dimension of the state ``(u, v, a, h, du, dv, da, dh)``."""

MEASUREMENT_DIM = 4
"""Dimension of a measurement ``(u, v, a, h)``."""

CHI2_95_4DOF = 9.4877
"""0.95 quantile of chi-square with 4 dof: the paper's and DeepSORT's Mahalanobis gate."""


@dataclass(frozen=True)
class KalmanConfig:
    """Noise parameters of the constant-velocity box filter (DeepSORT values).

    Position-like stds (u, v, h) are ``std_weight_position * h`` (1/20), velocity stds
    ``std_weight_velocity * h`` (1/160); at track start they are multiplied by
    ``initial_position_factor`` (2) and ``initial_velocity_factor`` (10). The aspect ratio has
    absolute stds ``aspect_std`` (1e-2), ``aspect_velocity_std`` (1e-5) and
    ``aspect_measurement_std`` (1e-1); ``time_step`` is in frames.
    """

    std_weight_position: float = 1.0 / 20.0
    std_weight_velocity: float = 1.0 / 160.0
    initial_position_factor: float = 2.0
    initial_velocity_factor: float = 10.0
    aspect_std: float = 1e-2
    aspect_velocity_std: float = 1e-5
    aspect_measurement_std: float = 1e-1
    time_step: float = 1.0

    def __post_init__(self) -> None:
        for name, value in vars(self).items():
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"KalmanConfig.{name} must be a positive number, got {value!r}")


def xywh_to_xyah(boxes: np.ndarray) -> np.ndarray:
    """Convert ``(n, 4)`` ``(x, y, w, h)`` boxes to ``float64`` measurements ``(u, v, a, h)``.

    >>> xywh_to_xyah(np.array([[10.0, 20.0, 4.0, 8.0]]))
    array([[12. , 24. ,  0.5,  8. ]])
    """
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    out = np.empty_like(b)
    out[:, 0] = b[:, 0] + b[:, 2] / 2.0
    out[:, 1] = b[:, 1] + b[:, 3] / 2.0
    with np.errstate(divide="ignore", invalid="ignore"):
        out[:, 2] = b[:, 2] / b[:, 3]
    out[:, 3] = b[:, 3]
    return out


def xyah_to_xywh(states: np.ndarray) -> np.ndarray:
    """Convert ``(u, v, a, h, ...)`` rows (first four columns read) to ``(x, y, w, h)`` boxes.

    >>> xyah_to_xywh(np.array([[12.0, 24.0, 0.5, 8.0]]))
    array([[10., 20.,  4.,  8.]])
    """
    s = np.asarray(states, dtype=np.float64)
    s = s.reshape(-1, s.shape[-1])[:, :4]
    w = s[:, 2] * s[:, 3]
    return np.stack([s[:, 0] - w / 2.0, s[:, 1] - s[:, 3] / 2.0, w, s[:, 3]], axis=1)


class KalmanFilter:
    """Batched constant-velocity Kalman filter on ``(u, v, a, h)`` and their velocities.

    Holds no track state: callers keep ``mean``/``covariance`` per track and pass stacked
    arrays, so one instance serves any number of tracks.

    Example:
        >>> kf = KalmanFilter()
        >>> mean, cov = kf.initiate(np.array([[50.0, 50.0, 0.5, 100.0]]))
        >>> mean, cov = kf.predict(mean, cov)
        >>> kf.gating_distance(mean, cov, np.array([[50.0, 50.0, 0.5, 100.0]])).shape
        (1, 1)
    """

    def __init__(self, config: KalmanConfig | None = None) -> None:
        self.config = config if config is not None else KalmanConfig()
        dt = self.config.time_step
        motion = np.eye(STATE_DIM)
        motion[:MEASUREMENT_DIM, MEASUREMENT_DIM:] = dt * np.eye(MEASUREMENT_DIM)
        self._motion = motion  # F: x_{t+1} = F x_t

    # ------------------------------------------------------------------ noise models
    def _position_like_std(self, height: np.ndarray, weight: float, aspect: float) -> np.ndarray:
        """Return ``(n, 4)`` stds ``(w*h, w*h, aspect, w*h)`` for heights ``(n,)``."""
        std = np.empty((len(height), MEASUREMENT_DIM))
        std[:, 0] = std[:, 1] = std[:, 3] = weight * height
        std[:, 2] = aspect
        return std

    def _process_covariance(self, height: np.ndarray) -> np.ndarray:
        """Return the ``(n, 8, 8)`` diagonal process noise ``Q`` for heights ``(n,)``."""
        c = self.config
        std = np.concatenate(
            [
                self._position_like_std(height, c.std_weight_position, c.aspect_std),
                self._position_like_std(height, c.std_weight_velocity, c.aspect_velocity_std),
            ],
            axis=1,
        )
        return _batched_diag(std**2)

    def _measurement_covariance(self, height: np.ndarray) -> np.ndarray:
        """Return the ``(n, 4, 4)`` diagonal measurement noise ``R`` for heights ``(n,)``."""
        c = self.config
        std = self._position_like_std(height, c.std_weight_position, c.aspect_measurement_std)
        return _batched_diag(std**2)

    # ------------------------------------------------------------------ filter steps
    def initiate(self, measurements: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Create ``(n, 8)`` states and diagonal covariances from first ``(n, 4)`` measurements."""
        z = _as_measurements(measurements, "measurements")
        c = self.config
        mean = np.concatenate([z, np.zeros_like(z)], axis=1)
        h = z[:, 3]
        std = np.concatenate(
            [
                self._position_like_std(
                    h, c.initial_position_factor * c.std_weight_position, c.aspect_std
                ),
                self._position_like_std(
                    h, c.initial_velocity_factor * c.std_weight_velocity, c.aspect_velocity_std
                ),
            ],
            axis=1,
        )
        return mean, _batched_diag(std**2)

    def predict(self, mean: np.ndarray, covariance: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Advance states by one step: ``x = F x``, ``P = F P F^T + Q``."""
        mean, covariance = _as_state(mean, covariance)
        q = self._process_covariance(mean[:, 3])
        new_mean = mean @ self._motion.T
        new_cov = self._motion @ covariance @ self._motion.T + q
        return new_mean, new_cov

    def project(self, mean: np.ndarray, covariance: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project ``(n, 8)`` states into measurement space: ``(H x, H P H^T + R)``."""
        mean, covariance = _as_state(mean, covariance)
        r = self._measurement_covariance(mean[:, 3])
        d = MEASUREMENT_DIM
        return mean[:, :d].copy(), covariance[:, :d, :d] + r

    def update(
        self, mean: np.ndarray, covariance: np.ndarray, measurements: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Correct states with one ``(u, v, a, h)`` measurement per track."""
        mean, covariance = _as_state(mean, covariance)
        z = _as_measurements(measurements, "measurements")
        if len(z) != len(mean):
            raise ValueError(
                f"update needs one measurement per track: got {len(z)} measurements "
                f"for {len(mean)} tracks"
            )
        proj_mean, proj_cov = self.project(mean, covariance)
        d = MEASUREMENT_DIM
        cross = covariance[:, :, :d]  # P H^T, (n, 8, 4)
        # K^T = S^-1 (P H^T)^T, solved rather than inverted (S is symmetric positive definite).
        gain = np.linalg.solve(proj_cov, cross.transpose(0, 2, 1)).transpose(0, 2, 1)
        innovation = z - proj_mean
        new_mean = mean + np.einsum("nij,nj->ni", gain, innovation)
        new_cov = covariance - gain @ proj_cov @ gain.transpose(0, 2, 1)
        new_cov = 0.5 * (new_cov + new_cov.transpose(0, 2, 1))  # keep it exactly symmetric
        return new_mean, new_cov

    def gating_distance(
        self, mean: np.ndarray, covariance: np.ndarray, measurements: np.ndarray
    ) -> np.ndarray:
        """``(n, m)`` squared Mahalanobis distances of measurements to predicted tracks (eq. cm).

        Compare with :data:`CHI2_95_4DOF` to gate.
        """
        mean, covariance = _as_state(mean, covariance)
        z = _as_measurements(measurements, "measurements")
        if len(mean) == 0 or len(z) == 0:
            return np.zeros((len(mean), len(z)))
        proj_mean, proj_cov = self.project(mean, covariance)
        diff = z[None, :, :] - proj_mean[:, None, :]  # (n, m, 4)
        chol = np.linalg.cholesky(proj_cov)  # (n, 4, 4), lower
        # Solve L y = diff^T per track; ||y||^2 is the squared Mahalanobis distance.
        y = np.linalg.solve(chol, diff.transpose(0, 2, 1))  # (n, 4, m)
        return np.einsum("nkm,nkm->nm", y, y)


def _batched_diag(values: np.ndarray) -> np.ndarray:
    """Return ``(n, k, k)`` diagonal matrices from ``(n, k)`` diagonals."""
    n, k = values.shape
    out = np.zeros((n, k, k))
    idx = np.arange(k)
    out[:, idx, idx] = values
    return out


def _as_measurements(values: np.ndarray, name: str) -> np.ndarray:
    z = np.asarray(values, dtype=np.float64)
    if z.ndim != 2 or z.shape[1] != MEASUREMENT_DIM:
        raise ValueError(f"{name} must have shape (n, 4) as (u, v, a, h), got {z.shape}")
    if not np.all(np.isfinite(z)):
        raise ValueError(f"{name} contain NaN or infinite values (a box with zero height?)")
    return z


def _as_state(mean: np.ndarray, covariance: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    m = np.asarray(mean, dtype=np.float64)
    p = np.asarray(covariance, dtype=np.float64)
    if m.ndim != 2 or m.shape[1] != STATE_DIM:
        raise ValueError(f"mean must have shape (n, 8), got {m.shape}")
    if p.shape != (len(m), STATE_DIM, STATE_DIM):
        raise ValueError(f"covariance must have shape ({len(m)}, 8, 8), got {p.shape}")
    return m, p
