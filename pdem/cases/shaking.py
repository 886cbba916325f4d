"""Rigid blocks under base motion (tests/verification/test_base_motion.py, docs/dynamics.md,
figure base-motion.png): Newmark's sliding block and Housner's rocking block.

The base is a block whose whole motion is prescribed (``boundary.velocity`` with a velocity
``history: {table: ...}``); a table is linear between rows, so a base acceleration that is
constant in pieces is a table of its velocities at the corners. No damping: every damping mode
falsifies dynamics.

Newmark's sliding block (Newmark 1965)
    A slab (friction ``phi``, no cohesion) on a horizontal base, or on an incline represented by
    tilting gravity, ``g = |g| (sin psi, 0, -cos psi)`` ("down the slope" is +x), as
    pdem.cases.incline does. The base gets a rectangular acceleration pulse ``A`` for ``T``:
    its velocity ramps to ``V = A T`` and stays there. Friction can give the slab, relative to
    the base, at most the yield acceleration

    * horizontal: ``a_y = g tan(phi)``;
    * incline, base pulse upslope (the slab slips downslope): ``a_y = g (cos psi tan phi -
      sin psi)``; base pulse downslope (it slips upslope): ``a_y = g (cos psi tan phi +
      sin psi)`` -- Newmark's asymmetry: the same shaking moves the slab down far more.

    Rigid-plastic closed form for ``A > a_y``: the slab accelerates at ``a_y`` from the pulse's
    start (the base at ``A``); the relative velocity grows as ``(A - a_y) t`` until ``T``, then
    (the base at constant ``V``) falls at ``a_y`` and dies at ``t1 = V / a_y``. The relative
    displacement is the area between the two velocity histories,

        d = int_0^T (A - a_y) t dt + int_T^t1 (V - a_y t) dt = V^2 / (2 a_y) (1 - a_y / A),

    and ``d = 0`` for ``A <= a_y`` (the slab rides with the base).

    Elastic start (the joint's shear spring, ``ks`` per unit area over the slab's whole base):
    friction cannot jump to its limit; the spring loads first. In the base's frame the lag
    ``u`` obeys ``u'' = A - w^2 u``, ``w^2 = ks A_c / m = ks / (rho h)`` (from the spring's
    preload on an incline), so the slab's acceleration ``w^2 u = A (1 - cos w t)`` reaches
    ``a_y`` at ``w t_s = arccos(c)``, ``c = 1 - a_y / A``, having gained ``dv = (A / w)(sin w
    t_s - c w t_s)`` less velocity than the rigid-plastic slab. From then on it slides at
    ``a_y`` exactly (Coulomb), ``dv`` behind, until it sticks ``dv / a_y`` later, so

        d_elastic = d + dv (t1 - t_s) + dv^2 / (2 a_y)     (to ~a_y / w^2 ~ 1e-6 m).

    The relative size of the correction is ``2 dv / ((A - a_y) T)``: 2.0 % for A = 1.5 a_y,
    T = 0.1 s, kn = ks = 1e9 Pa/m on a 0.2 m slab; it vanishes as ``ks`` grows.

Housner's rocking block (Housner 1963)
    A slender rectangular block, half-width ``b`` (along x), half-height ``h``, on a rigid base;
    ``R = sqrt(b^2 + h^2)``, ``alpha = atan(b / h)``, and about a bottom corner ``I_0 = 4/3 m
    R^2``, so ``p = sqrt(m g R / I_0) = sqrt(3 g / (4 R))``. Rocking by ``theta`` about a corner
    (theta > 0 tilts the centroid towards it):

        theta'' = p^2 [ (a / g) cos(alpha - theta) - sin(alpha - theta) ]

    for a base acceleration ``a`` away from the corner. So the block lifts off when ``a >
    g tan(alpha)`` (a quasi-static load: a sudden step on elastic contacts overshoots), and
    released at rest from ``theta0`` with ``a = 0`` it falls back onto its base (the first
    impact, theta = 0) after

        t = (1/p) arccosh(1 / (1 - theta0 / alpha))     (Housner, for sin x ~ x),

    which :func:`pivot_impact_time` computes without the small-angle step. Across the impact
    Housner's rigid block keeps its angular momentum about the new corner (a plastic impact):
    ``w_after / w_before = 1 - 3/2 sin^2(alpha)``.
"""

from __future__ import annotations

import math

import numpy as np

from pdem.cases import rotation_matrix, vec

G = 9.81
RHO = 2000.0
KN = 1.0e9  # kn = ks, Pa/m
PHI = 30.0  # slab's friction angle, degrees
PSI = 10.0  # incline angle, degrees
SLAB_H = 0.2  # the slab: 1 x 1 m, 0.2 m thick (flat, so the friction moment cannot tip it)
SETTLE_STEPS = 3000  # the incline's static stage (local damping) before the shaking

# the rocking block: half-width (x), half-height, half-depth (y); alpha = 11.3 deg
ROCK_B, ROCK_H, ROCK_D = 0.2, 1.0, 0.2
ROCK_FRICTION = 60.0  # no slip at the pivot corner


# ------------------------------------------------------------------ Newmark's sliding block
def yield_acceleration(psi: float = 0.0, slip: str = "down", phi: float = PHI) -> float:
    """``g (cos psi tan phi -+ sin psi)`` (degrees): the base acceleration at which the slab
    starts to slip ``down`` (base pulse upslope, -x) or ``up`` the slope (base pulse downslope,
    +x); ``psi = 0``: ``g tan phi`` either way."""
    s, p = math.radians(psi), math.radians(phi)
    sign = -1.0 if slip == "down" else 1.0
    return G * (math.cos(s) * math.tan(p) + sign * math.sin(s))


def newmark_displacement(a: float, duration: float, a_y: float) -> float:
    """Newmark's permanent slip of a rigid-plastic block under a rectangular base acceleration
    pulse ``a`` for ``duration``: ``V^2 / (2 a_y) (1 - a_y / a)``, ``V = a duration``; 0 when
    ``a <= a_y``."""
    if a <= a_y:
        return 0.0
    v = a * duration
    return v * v / (2.0 * a_y) * (1.0 - a_y / a)


def newmark_slip(t, a: float, duration: float, a_y: float):
    """The rigid-plastic slip history ``d(t)`` (array ``t``, s) of :func:`newmark_displacement`:
    relative velocity ``(a - a_y) t`` up to ``duration``, then falling at ``a_y`` to zero."""
    t = np.asarray(t, float)
    if a <= a_y:
        return np.zeros_like(t)
    v_end = (a - a_y) * duration
    t1 = a * duration / a_y
    during = 0.5 * (a - a_y) * np.minimum(t, duration) ** 2
    s = np.clip(t, duration, t1) - duration
    return during + v_end * s - 0.5 * a_y * s * s


def shear_frequency() -> float:
    """``w = sqrt(ks A_c / m) = sqrt(ks / (rho h))`` of the slab on its shear spring (rad/s)."""
    return math.sqrt(KN / (RHO * SLAB_H))


def newmark_elastic_displacement(a: float, duration: float, a_y: float) -> float:
    """Newmark's slip with the elastic start of the shear spring (module docstring):
    ``d + dv (t1 - t_s) + dv^2 / (2 a_y)``."""
    if a <= a_y:
        return 0.0
    w = shear_frequency()
    c = 1.0 - a_y / a
    ws = math.acos(c)  # w t_s
    dv = a / w * (math.sin(ws) - c * ws)
    t1 = a * duration / a_y
    return newmark_displacement(a, duration, a_y) + dv * (t1 - ws / w) + dv * dv / (2.0 * a_y)


def slip_time(a: float, duration: float, a_y: float) -> float:
    """When the rigid-plastic slab sticks again: ``t1 = a duration / a_y`` (0 if it never
    slips)."""
    return a * duration / a_y if a > a_y else 0.0


def pulse_table(a: float, duration: float, ramp: float = 0.0, rows: int = 20) -> str:
    """The base's x velocity (YAML table) for an acceleration ``a`` (m/s^2, +x downslope) held
    for ``duration``, then constant velocity. ``ramp > 0``: the acceleration first grows
    linearly from 0 over ``ramp`` (inside ``duration``), in ``rows`` steps -- slow against the
    contact's elastic period, so that the load is quasi-static (no dynamic overshoot)."""
    pts = [(0.0, 0.0)]
    if ramp > 0.0:
        for k in range(1, rows + 1):
            t = ramp * k / rows
            pts.append((t, a * t * t / (2.0 * ramp)))
    v_ramp = a * ramp / 2.0
    pts.append((duration, v_ramp + a * (duration - ramp)))
    return "[" + ", ".join(vec((t, v, 0.0, 0.0)) for t, v in pts) + "]"


def sliding_scene(a: float, duration: float, time: float, psi: float = 0.0,
                  ramp: float = 0.0) -> str:
    """The base (10 x 4 x 1 m) and the slab at its static normal overlap, friction PHI; the
    base gets :func:`pulse_table` for ``time`` s. ``psi > 0``: gravity tilted by ``psi`` and a
    static stage first (base fixed, local damping, SETTLE_STEPS: the shear spring takes the
    slab's downslope weight), then the shaking stage (no damping; the history's clock starts
    with it). Horizontal: the shaking from the start, no damping (nothing to settle)."""
    s = math.radians(psi)
    g = (G * math.sin(s), 0.0, -G * math.cos(s))
    delta = RHO * SLAB_H * G * math.cos(s) / KN  # m g cos(psi) / (kn A), A = 1 m^2
    head = f"""
name: shaking-slab
gravity: {vec(g)}
materials: {{rock: {{density: {RHO}}}}}
joints: {{default: {{kn: {KN}, ks: {KN}, friction: {PHI}}}}}
blocks:
  - {{name: base, box: {{min: [-5, -2, -1], max: [5, 2, 0]}}, material: rock, fixed: true}}
  - name: slab
    box: {{min: {vec((-0.5, -0.5, -delta))}, max: {vec((0.5, 0.5, SLAB_H - delta))}}}
    material: rock
"""
    shake = f"velocity: [{{names: [base], history: {{table: {pulse_table(a, duration, ramp)}}}}}]"
    if psi == 0.0:
        return head + f"""boundary:
  {shake}
solve: {{time: {time}, damping: none}}
"""
    return head + f"""solve: {{damping: local}}
stages:
  - {{name: settle, solve: {{steps: {SETTLE_STEPS}}}}}
  - name: shake
    {shake}
    solve: {{time: {time}, damping: none}}
"""


# ------------------------------------------------------------------ Housner's rocking block
def rocking_constants() -> tuple[float, float, float]:
    """``(alpha, R, p)`` of the rocking block: ``atan(b/h)``, ``sqrt(b^2 + h^2)``,
    ``sqrt(3 g / (4 R))``."""
    r = math.hypot(ROCK_B, ROCK_H)
    return math.atan(ROCK_B / ROCK_H), r, math.sqrt(3.0 * G / (4.0 * r))


def rocking_mass() -> float:
    """The rocking block's mass, ``rho 8 b h d``."""
    return RHO * 8.0 * ROCK_B * ROCK_H * ROCK_D


def uplift_acceleration() -> float:
    """Housner's uplift threshold ``g tan(alpha) = g b / h``."""
    return G * ROCK_B / ROCK_H


def elastic_tilt(a: float) -> float:
    """The upright block's tilt on its base's springs under a steady base acceleration ``a``:
    the overturning moment ``m a h`` over the rotational stiffness of the face contact's four
    corner springs (each ``kn A_c / 4`` at ``x = +-b``), ``kn A_c b^2``."""
    area = 4.0 * ROCK_B * ROCK_D
    return rocking_mass() * a * ROCK_H / (KN * area * ROCK_B * ROCK_B)


def uplift_scene(a: float, ramp: float, time: float) -> str:
    """The upright block at its static overlap on a 4 x 2 m base whose acceleration grows
    linearly to ``a`` over ``ramp`` and then stays (:func:`pulse_table`, 50 rows), ``time``
    s, no damping."""
    m = rocking_mass()
    delta = m * G / (KN * 4.0 * ROCK_B * ROCK_D)
    return f"""
name: rocking-uplift
gravity: [0, 0, {-G}]
materials: {{rock: {{density: {RHO}}}}}
joints: {{default: {{kn: {KN}, ks: {KN}, friction: {ROCK_FRICTION}}}}}
blocks:
  - {{name: base, box: {{min: [-2, -1, -0.5], max: [2, 1, 0]}}, material: rock}}
  - name: rocker
    box: {{min: {vec((-ROCK_B, -ROCK_D, -delta))}, max: {vec((ROCK_B, ROCK_D, 2 * ROCK_H - delta))}}}
    material: rock
boundary:
  velocity: [{{names: [base], history: {{table: {pulse_table(a, time, ramp, 50)}}}}}]
solve: {{time: {time}, damping: none}}
"""


def tilted_scene(theta0: float, time: float, damping: str = "none") -> str:
    """The block tilted by ``theta0`` (rad) about its bottom +x edge, which rests on a fixed
    base (4 x 2 m) at the static overlap of its two point springs (area ``contact.point_area
    V^(2/3)`` each, the default point_area 0.01), its -x bottom edge lifted by ``2 b
    sin(theta0)`` (a +y rotation, :func:`tilt_about_y`); released at rest, ``time`` s, no
    damping (or ``damping``, ``solve.damping`` as YAML flow). It falls back towards upright,
    pivoting on the +x edge."""
    vol = 8.0 * ROCK_B * ROCK_H * ROCK_D
    delta = RHO * vol * G / (2.0 * KN * 0.01 * vol ** (2.0 / 3.0))
    c, s = math.cos(theta0), math.sin(theta0)
    verts = [(x * c + z * s, y, -x * s + z * c - delta)
             for x in (-2.0 * ROCK_B, 0.0) for y in (-ROCK_D, ROCK_D) for z in (0.0, 2.0 * ROCK_H)]
    return f"""
name: rocking-free
gravity: [0, 0, {-G}]
materials: {{rock: {{density: {RHO}}}}}
joints: {{default: {{kn: {KN}, ks: {KN}, friction: {ROCK_FRICTION}}}}}
blocks:
  - {{name: base, box: {{min: [-2, -1, -0.5], max: [2, 1, 0]}}, material: rock, fixed: true}}
  - name: rocker
    polyhedron: {{vertices: [{", ".join(vec(v) for v in verts)}]}}
    material: rock
solve: {{time: {time}, damping: {damping}}}
"""


def tilt_about_y(q, r0: np.ndarray) -> float:
    """The rotation (rad) about +y of the block whose orientation is ``q`` relative to its
    initial rotation matrix ``r0``: x towards -z is positive (a +y rotation)."""
    rr = rotation_matrix(q) @ r0.T
    return math.atan2(rr[0, 2], rr[0, 0])


def _rk4(f, y, t, h, stop):
    """Integrate ``y' = f(t, y)`` (2-vectors as tuples) with step ``h`` until ``stop(t, y)``
    is true; returns the last two ``(t, y)``."""
    while True:
        k1 = f(t, y)
        k2 = f(t + h / 2, (y[0] + h / 2 * k1[0], y[1] + h / 2 * k1[1]))
        k3 = f(t + h / 2, (y[0] + h / 2 * k2[0], y[1] + h / 2 * k2[1]))
        k4 = f(t + h, (y[0] + h * k3[0], y[1] + h * k3[1]))
        yn = (y[0] + h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0]),
              y[1] + h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1]))
        if stop(t + h, yn):
            return (t, y), (t + h, yn)
        t, y = t + h, yn


def housner_impact_time(theta0: float) -> float:
    """Housner's small-angle time to the first impact, ``(1/p) arccosh(1 / (1 - theta0 /
    alpha))``."""
    alpha, _, p = rocking_constants()
    return math.acosh(1.0 / (1.0 - theta0 / alpha)) / p


def pivot_impact_time(theta0: float, h: float = 1e-5, drag: float = 0.0) -> tuple[float, float]:
    """``(t, w)``: time to the first impact and the angular velocity then, of the rigid block
    pivoting from rest at ``theta0`` (``theta'' = -p^2 sin(alpha - theta)``, RK4 with step
    ``h``, the crossing of theta = 0 interpolated linearly). ``drag`` (1/s): a viscous force
    ``-drag m v`` and moment ``-drag I_c w`` on the block (Rayleigh damping's mass term), whose
    moment about the pivot is ``-drag I_0 w``: ``theta'' = -p^2 sin(alpha - theta) - drag
    theta'``."""
    alpha, _, p = rocking_constants()
    (t0, y0), (t1, y1) = _rk4(lambda t, y: (y[1], -p * p * math.sin(alpha - y[0]) - drag * y[1]),
                              (theta0, 0.0), 0.0, h, lambda t, y: y[0] <= 0.0)
    f = y0[0] / (y0[0] - y1[0])
    return t0 + f * (t1 - t0), y0[1] + f * (y1[1] - y0[1])


def uplift_tilt(a: float, ramp: float, time: float, h: float = 1e-5) -> float:
    """The rigid block's rocking angle at ``time`` under the ramped base acceleration of
    :func:`uplift_scene` (``a`` above the threshold): ``theta'' = p^2 [(a(t)/g) cos(alpha -
    theta) - sin(alpha - theta)]`` from rest at theta = 0 when ``a(t)`` crosses ``g tan
    alpha``."""
    alpha, _, p = rocking_constants()
    t_on = ramp * uplift_acceleration() / a

    def f(t, y):
        acc = a * min(t, ramp) / ramp
        return y[1], p * p * (acc / G * math.cos(alpha - y[0]) - math.sin(alpha - y[0]))

    steps = max(1, int(math.ceil((time - t_on) / h)))
    (_, _), (_, y) = _rk4(f, (0.0, 0.0), t_on, (time - t_on) / steps,
                          lambda t, y: t >= time - 1e-12)
    return y[0]


def housner_restitution() -> float:
    """Housner's angular velocity ratio across an impact, ``1 - 3/2 sin^2(alpha)``."""
    alpha, _, _ = rocking_constants()
    return 1.0 - 1.5 * math.sin(alpha) ** 2
