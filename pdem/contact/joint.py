"""Joint constitutive models: the Coulomb-slip joint of 3DEC (eqs. 34-43).

Joint models are selected by name from ``JOINT_MODELS``; a new model is a new kernel with the
``coulomb_slip`` signature plus an entry here.
"""

from __future__ import annotations

import math

import numpy as np

from ..jit import kernel

# sub-contact state bits
SLIPPING = 1  # at the shear limit this step
FAILED = 2  # tension and cohesion lost (eqs. 36-37), for good
OPEN = 4  # normal force zero: separated


@kernel
def coulomb_slip(un, dil, fx, fy, fz, dx, dy, dz, area, kn, tan_phi, tan_psi, cohesion,
                 tension, us_lim, ux, uy, uz, state):
    """Update one sub-contact's normal and shear force (eqs. 24-27, 34-43).

    Scalars only, so the force loop keeps everything in registers.

    Parameters
    ----------
    un : overlap of the surfaces (+ closing); normal force is ``kn * area * (un + dil)``, the
        total form of eqs. 24, 26, 43.
    dil : accumulated dilation (eq. 42).
    fx, fy, fz : trial shear force on block B, already carrying this step's elastic increment
        (eqs. 25, 27).
    dx, dy, dz : this step's shear displacement increment (eq. 22), for dilation (eq. 41).
    ux, uy, uz : total shear displacement after this step, for the dilation limit.
    state : state bits (SLIPPING, FAILED, OPEN).

    Returns
    -------
    (fn, dil, state, fx, fy, fz)
    """
    state = state & FAILED
    fn = kn * area * (un + dil)
    t_max = 0.0 if state & FAILED else tension * area  # eq. 34, 36
    c_area = 0.0 if state & FAILED else cohesion * area
    if fn < -t_max:  # eq. 38: tensile failure
        if t_max > 0.0 or c_area > 0.0:
            state |= FAILED
        return 0.0, dil, state | OPEN, 0.0, 0.0, 0.0
    fs_max = c_area + max(fn, 0.0) * tan_phi  # eq. 35, 37
    fs_mag = math.sqrt(fx * fx + fy * fy + fz * fz)
    if fs_mag > fs_max:  # eq. 39
        scale = fs_max / fs_mag
        fx *= scale
        fy *= scale
        fz *= scale
        state |= SLIPPING
        if t_max > 0.0 or c_area > 0.0:
            state |= FAILED
        if tan_psi > 0.0:
            # Dilation only while slipping (eq. 41-42), growing when the increment follows the
            # accumulated shear and shrinking when it reverses; none past the limit.
            dus_mag = math.sqrt(dx * dx + dy * dy + dz * dz)
            us_mag = math.sqrt(ux * ux + uy * uy + uz * uz)
            if us_mag < us_lim:
                sign = 1.0 if dx * ux + dy * uy + dz * uz >= 0.0 else -1.0
                dil = max(dil + sign * dus_mag * tan_psi, 0.0)
                fn = kn * area * (un + dil)  # eq. 43
    if fn <= 0.0:
        state |= OPEN
        fn = min(fn, 0.0)
    return fn, dil, state, fx, fy, fz


JOINT_MODELS = {"coulomb": 0}


def joint_table(scene, group_names: list[str]):
    """Arrays of joint properties (one row per scene joint) and the group-pair -> row map.

    Angles become tangents here, once, so kernels never see degrees."""
    names = list(scene.joints)
    rows = {name: i for i, name in enumerate(names)}
    j = [scene.joints[k] for k in names]
    table = {
        "kn": np.array([x.kn for x in j]),
        "ks": np.array([x.ks for x in j]),
        "tan_phi": np.array([math.tan(math.radians(x.friction)) for x in j]),
        "tan_psi": np.array([math.tan(math.radians(x.dilation)) for x in j]),
        "cohesion": np.array([x.cohesion for x in j]),
        "tension": np.array([x.tension for x in j]),
        "us_lim": np.array([x.dilation_limit or np.inf for x in j]),
    }
    ng = len(group_names)
    default = rows.get("default", 0)
    pair = np.full((ng, ng), default, dtype=np.int32)
    gidx = {g: i for i, g in enumerate(group_names)}
    for jp in scene.joint_pairs:
        a, b = gidx[jp.groups[0]], gidx[jp.groups[1]]
        pair[a, b] = pair[b, a] = rows[jp.joint]
    return table, pair, names
