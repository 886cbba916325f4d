"""Quaternion helpers as numba kernels.

Convention (docs/architecture.md): unit quaternions ``(w, x, y, z)`` rotating body-frame
vectors into the world frame, ``v_world = R(q) v_body``.  Composition ``quat_mul(a, b)`` is the
Hamilton product, so ``R(a ⊗ b) = R(a) R(b)``: a *world-frame* rotation ``dq`` is applied as
``dq ⊗ q``.

The public functions take and return small numpy arrays.  The ``_s`` variants work on scalars
and return tuples; the integrator uses those so the hot loop allocates nothing.
"""

from __future__ import annotations

import math

import numpy as np

from pdem.jit import kernel

# Below this rotation angle (rad) sin(h)/angle uses its Taylor series (error < 1e-25).
_SMALL_ANGLE = 1.0e-3


# --------------------------------------------------------------------------- scalar forms


@kernel
def quat_mul_s(aw, ax, ay, az, bw, bx, by, bz):
    """Hamilton product a ⊗ b on scalars; returns (w, x, y, z)."""
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


@kernel
def quat_from_rotvec_s(tx, ty, tz):
    """Exact unit quaternion of the rotation vector (tx, ty, tz) (axis * angle)."""
    a2 = tx * tx + ty * ty + tz * tz
    angle = math.sqrt(a2)
    if angle < _SMALL_ANGLE:
        # h = angle/2; sin(h)/angle = (1 - h^2/6 + h^4/120 - h^6/5040) / 2; cos(h) series.
        h2 = 0.25 * a2
        s = 0.5 * (1.0 - h2 / 6.0 * (1.0 - h2 / 20.0 * (1.0 - h2 / 42.0)))
        c = 1.0 - h2 / 2.0 * (1.0 - h2 / 12.0 * (1.0 - h2 / 30.0 * (1.0 - h2 / 56.0)))
    else:
        h = 0.5 * angle
        s = math.sin(h) / angle
        c = math.cos(h)
    return c, s * tx, s * ty, s * tz


@kernel
def quat_normalize_s(w, x, y, z):
    n = math.sqrt(w * w + x * x + y * y + z * z)
    inv = 1.0 / n
    return w * inv, x * inv, y * inv, z * inv


@kernel
def quat_to_matrix_s(w, x, y, z):
    """Rotation matrix of a unit quaternion, row-major 9-tuple."""
    xx = x * x
    yy = y * y
    zz = z * z
    xy = x * y
    xz = x * z
    yz = y * z
    wx = w * x
    wy = w * y
    wz = w * z
    return (
        1.0 - 2.0 * (yy + zz),
        2.0 * (xy - wz),
        2.0 * (xz + wy),
        2.0 * (xy + wz),
        1.0 - 2.0 * (xx + zz),
        2.0 * (yz - wx),
        2.0 * (xz - wy),
        2.0 * (yz + wx),
        1.0 - 2.0 * (xx + yy),
    )


@kernel
def rotate_s(w, x, y, z, vx, vy, vz):
    """R(q) v for unit q: v + 2 w (u x v) + 2 u x (u x v), u = (x, y, z)."""
    cx = y * vz - z * vy
    cy = z * vx - x * vz
    cz = x * vy - y * vx
    return (
        vx + 2.0 * (w * cx + y * cz - z * cy),
        vy + 2.0 * (w * cy + z * cx - x * cz),
        vz + 2.0 * (w * cz + x * cy - y * cx),
    )


@kernel
def rotate_inv_s(w, x, y, z, vx, vy, vz):
    """R(q)^T v (world -> body) for unit q."""
    return rotate_s(w, -x, -y, -z, vx, vy, vz)


# --------------------------------------------------------------------------- array forms


@kernel
def quat_mul(a, b):
    """Hamilton product ``a ⊗ b`` of two (4,) quaternions."""
    r = quat_mul_s(a[0], a[1], a[2], a[3], b[0], b[1], b[2], b[3])
    out = np.empty(4)
    out[0], out[1], out[2], out[3] = r
    return out


@kernel
def quat_conj(q):
    out = np.empty(4)
    out[0] = q[0]
    out[1] = -q[1]
    out[2] = -q[2]
    out[3] = -q[3]
    return out


@kernel
def quat_from_rotvec(theta):
    """Unit quaternion of rotation vector ``theta`` (3,); exact, stable for tiny angles."""
    r = quat_from_rotvec_s(theta[0], theta[1], theta[2])
    out = np.empty(4)
    out[0], out[1], out[2], out[3] = r
    return out


@kernel
def quat_to_rotvec(q):
    """Rotation vector (axis * angle, angle in [0, pi]) of a unit quaternion."""
    w = q[0]
    x = q[1]
    y = q[2]
    z = q[3]
    if w < 0.0:
        w = -w
        x = -x
        y = -y
        z = -z
    s = math.sqrt(x * x + y * y + z * z)
    angle = 2.0 * math.atan2(s, w)
    if s < 1e-300:
        f = 2.0
    else:
        f = angle / s
    out = np.empty(3)
    out[0] = f * x
    out[1] = f * y
    out[2] = f * z
    return out


@kernel
def quat_normalize(q):
    r = quat_normalize_s(q[0], q[1], q[2], q[3])
    out = np.empty(4)
    out[0], out[1], out[2], out[3] = r
    return out


@kernel
def quat_to_matrix(q):
    """(3, 3) rotation matrix (body -> world) of a unit quaternion."""
    m = quat_to_matrix_s(q[0], q[1], q[2], q[3])
    out = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            out[i, j] = m[3 * i + j]
    return out


@kernel
def rotate(q, v):
    """R(q) v for a (3,) vector."""
    r = rotate_s(q[0], q[1], q[2], q[3], v[0], v[1], v[2])
    out = np.empty(3)
    out[0], out[1], out[2] = r
    return out


@kernel
def rotate_inv(q, v):
    """R(q)^T v for a (3,) vector (world -> body)."""
    r = rotate_inv_s(q[0], q[1], q[2], q[3], v[0], v[1], v[2])
    out = np.empty(3)
    out[0], out[1], out[2] = r
    return out
