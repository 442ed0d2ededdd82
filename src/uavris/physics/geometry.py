"""UAV attitude and RIS geometry (paper eq. 10, 11-12 and Remark 1).

All functions are pure and batched over leading dimensions.

Lives here: :func:`wrap_angle`, :func:`accumulate_attitude`, :func:`rotation_matrix`,
:func:`ris_axes`, :func:`incidence` and the attitude safety layer (:func:`worst_elevation`,
:func:`clear_attitude`). Not here: the UAV's position and velocity
(:mod:`.motion`) and what the incidence feeds: the array response and back-side blocking
(:mod:`.channel`), the angle-dependent reflection (:mod:`.reflection`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

TWO_PI = 2.0 * np.pi


def wrap_angle(angle: ArrayLike) -> NDArray[np.float64]:
    """Wrap angles to [0, 2*pi) (paper constraint 13e)."""
    w = np.mod(np.asarray(angle, dtype=np.float64), TWO_PI)
    # np.mod can return exactly 2*pi for tiny negative inputs; fold it back.
    return np.where(w >= TWO_PI, 0.0, w)


def accumulate_attitude(attitude: ArrayLike, increment: ArrayLike) -> NDArray[np.float64]:
    """zeta(t+1) = wrap(zeta(t) + delta_zeta(t)), attitude = (yaw, pitch, roll) (docs/model.md section 1)."""
    return wrap_angle(np.asarray(attitude, dtype=np.float64) + np.asarray(increment, dtype=np.float64))


def rotation_matrix(yaw: ArrayLike, pitch: ArrayLike, roll: ArrayLike) -> NDArray[np.float64]:
    """R = Rz(yaw) @ Ry(pitch) @ Rx(roll), paper eq. (10). Shape ``(..., 3, 3)``."""
    y, p, r = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (yaw, pitch, roll)))
    cy, sy, cp, sp, cr, sr = np.cos(y), np.sin(y), np.cos(p), np.sin(p), np.cos(r), np.sin(r)
    R = np.empty(y.shape + (3, 3))
    # Product of the three elementary rotations written out, so the batch costs one pass.
    R[..., 0, 0] = cy * cp
    R[..., 0, 1] = cy * sp * sr - sy * cr
    R[..., 0, 2] = cy * sp * cr + sy * sr
    R[..., 1, 0] = sy * cp
    R[..., 1, 1] = sy * sp * sr + cy * cr
    R[..., 1, 2] = sy * sp * cr - cy * sr
    R[..., 2, 0] = -sp
    R[..., 2, 1] = cp * sr
    R[..., 2, 2] = cp * cr
    return R


def ris_axes(attitude: ArrayLike) -> NDArray[np.float64]:
    """RIS axes for an absolute attitude ``(..., 3)`` = (yaw, pitch, roll) (Remark 1).

    Returns ``(..., 3, 3)`` whose columns are e_x, e_y and the normal n, i.e. the
    reference axes rotated once by R(zeta) (never compounded slot after slot).
    A level RIS has e_x = [1,0,0], e_y = [0,1,0], n = [0,0,1].
    """
    att = np.asarray(attitude, dtype=np.float64)
    return rotation_matrix(att[..., 0], att[..., 1], att[..., 2])


def incidence(
    uav_pos: ArrayLike, user_pos: ArrayLike, axes: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Spatial frequencies and incidence of each user at the RIS (Remark 1, eq. 11-12).

    Args:
        uav_pos: ``(..., 3)`` RIS/UAV position q_U.
        user_pos: ``(K, 3)`` or ``(..., K, 3)`` user positions q_k.
        axes: ``(..., 3, 3)`` from :func:`ris_axes`.

    Returns:
        ``(u, v, cos_theta, dist)``, each ``(..., K)``, with d_k = q_U - q_k,
        u = <d, e_x>/|d|, v = <d, e_y>/|d|, cos(theta) = <d, n>/|d|.
    """
    q = np.asarray(uav_pos, dtype=np.float64)
    users = np.asarray(user_pos, dtype=np.float64)
    d = q[..., None, :] - users  # (..., K, 3)
    dist = np.sqrt(np.sum(d * d, axis=-1))
    # Projections on the three rotated axes at once: local[..., k, j] = <d_k, axis_j>.
    local = np.matmul(d, np.asarray(axes, dtype=np.float64))
    inv = 1.0 / np.maximum(dist, 1e-12)
    return local[..., 0] * inv, local[..., 1] * inv, local[..., 2] * inv, dist


def worst_elevation(attitude: ArrayLike, uav_pos: ArrayLike, user_pos: ArrayLike) -> NDArray[np.float64]:
    """``min_k cos(theta_k)`` ``(...)``: the sine of the lowest device's elevation above the RIS
    plane, seen from the RIS (negative: that device is behind the plane, docs/model.md section 3)."""
    return incidence(uav_pos, user_pos, ris_axes(attitude))[2].min(axis=-1)


def clear_attitude(attitude: ArrayLike, increment: ArrayLike, uav_pos: ArrayLike, user_pos: ArrayLike,
                   margin_rad: float, step_rad: float, iterations: int = 30) -> NDArray[np.float64]:
    """The attitude safety layer: the attitude increment ``(..., 3)`` executed instead of ``increment``.

    The floor is every device ``margin_rad`` in front of the RIS plane (its elevation seen from
    the RIS at ``uav_pos``, the UAV's position after the slot's move), or as far in front as
    the increment towards level allows (at most ``step_rad`` per angle; a level RIS has every
    device in front, since they all stand below the UAV's floor). An increment that keeps the
    floor is executed unchanged; any other is moved towards the level-ward increment just far
    enough to keep it (bisection on the segment between the two, ``iterations`` halvings). So
    a policy steers freely where nothing can be blocked, and a tilt that would put a device
    behind the plane (a few degrees suffice at the UAV's floor, and every pair with that device
    is lost, docs/model.md section 3) is cut at the margin, like the safety separation cuts a
    move at the devices' balls (:mod:`.motion`).
    """
    att = np.asarray(attitude, dtype=np.float64)
    inc = np.asarray(increment, dtype=np.float64)
    users = np.asarray(user_pos, dtype=np.float64)
    tilt = np.mod(att + np.pi, TWO_PI) - np.pi  # the attitude as angles in [-pi, pi)
    level = np.clip(-tilt, -step_rad, step_rad)  # one slot's turn towards level
    floor = np.minimum(np.sin(margin_rad), worst_elevation(att + level, uav_pos, users))
    ok = worst_elevation(att + inc, uav_pos, users) >= floor
    if np.all(ok):
        return inc
    lo, hi = np.zeros(floor.shape), np.ones(floor.shape)  # share of the way to level: hi keeps the floor
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        keeps = worst_elevation(att + inc + mid[..., None] * (level - inc), uav_pos, users) >= floor
        lo, hi = np.where(keeps, lo, mid), np.where(keeps, mid, hi)
    return np.where(ok[..., None], inc, inc + hi[..., None] * (level - inc))
