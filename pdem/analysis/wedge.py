"""Limit equilibrium of a rock wedge resting on two joint planes (dry, cohesionless).

References: E. Hoek and J. W. Bray, *Rock Slope Engineering*, 3rd ed. (1981), chapter 8
"Wedge failure" and appendix 2 (the comprehensive solution); D. C. Wyllie and C. W. Mah,
*Rock Slope Engineering*, 4th ed. (2004), chapter 7 and appendix III (the same vector method).

Conventions (those of the scene file and of :func:`pdem.geometry.cutting.dip_normal`): x = east,
y = north, z = up; dip in degrees below horizontal in ``[0, 90]``; dip direction in degrees
clockwise from north (+y). A plane's upward unit normal is

    n = (sin(dip) sin(dd), sin(dip) cos(dd), cos(dip)).

The wedge lies on the upper side of both planes, ``{n1.x >= 0} & {n2.x >= 0}``, so plane i
pushes on it with a force ``N_i n_i``, ``N_i >= 0`` while in contact.

Only the orientations of the two planes and the direction of gravity enter: the weight W,
the slope face and the upper surface scale every force alike and drop out of the factor of
safety when there is neither cohesion nor water pressure. Whether the line of intersection
daylights in the slope face (the kinematic test of a stereonet) is the caller's business.
"""

from __future__ import annotations

import math

import numpy as np

from pdem.geometry.cutting import dip_normal
from pdem.geometry.errors import GeometryError

__all__ = ["bolted_wedge_factor_of_safety", "critical_friction", "intersection_line",
           "normal_reactions", "wedge_factor_of_safety"]

# |n1 x n2| below this: the planes are parallel and make no wedge
_PARALLEL = 1e-9
# driving component (per unit weight) below this: nothing pulls the wedge along its path
_NO_DRIVE = 1e-12


def _unit_gravity(gravity) -> np.ndarray:
    g = np.asarray(gravity, dtype=float).reshape(3)
    norm = float(np.linalg.norm(g))
    if not np.isfinite(norm) or norm == 0.0:
        raise GeometryError(f"gravity must be a finite non-zero vector, got {gravity!r}")
    return g / norm


def _line(n1: np.ndarray, n2: np.ndarray) -> np.ndarray:
    d = np.cross(n1, n2)
    norm = float(np.linalg.norm(d))
    if norm < _PARALLEL:
        raise GeometryError("the two planes are parallel: they make no wedge")
    d /= norm
    # down-plunge; a horizontal line is oriented to a trend in [0, 180)
    if d[2] > 0.0 or (d[2] == 0.0 and (d[0] < 0.0 or (d[0] == 0.0 and d[1] < 0.0))):
        d = -d
    return d


def intersection_line(dip1: float, dd1: float, dip2: float, dd2: float) -> tuple[float, float, np.ndarray]:
    """Line of intersection of two planes: ``(plunge_deg, trend_deg, d)``.

    ``d = +-(n1 x n2)/|n1 x n2|`` is the unit vector pointing down-plunge (``d_z <= 0``);
    plunge = ``asin(-d_z)`` in ``[0, 90]``, trend = ``atan2(d_x, d_y)`` in ``[0, 360)``
    (clockwise from north, the azimuth of the down-plunge direction). A horizontal line
    (plunge 0) gets the trend in ``[0, 180)``. Parallel planes raise
    :class:`~pdem.geometry.errors.GeometryError`.
    """
    d = _line(dip_normal(dip1, dd1), dip_normal(dip2, dd2))
    plunge = math.degrees(math.asin(min(1.0, max(0.0, -float(d[2])))))
    trend = math.degrees(math.atan2(float(d[0]), float(d[1]))) % 360.0
    if trend >= 360.0:  # a tiny negative angle wraps to exactly 360.0
        trend -= 360.0
    return plunge, trend, d


def normal_reactions(dip1: float, dd1: float, dip2: float, dd2: float,
                     gravity=(0.0, 0.0, -1.0)) -> tuple[float, float, float]:
    """Normal reactions per unit weight for sliding along the line of intersection:
    ``(N1, N2, driving)``.

    With ``w`` the unit weight vector and ``s = +-d`` the direction along the line of
    intersection in which the weight pulls (``w.s >= 0``), the weight splits into the driving
    component ``driving = w.s`` (= ``sin(psi_i)``, psi_i the plunge, for vertical gravity) and
    the part normal to the line, ``w_perp = w - (w.s) s``, which the planes carry:

        N1 n1 + N2 n2 = -w_perp,    c = n1.n2,
        N1 = -(w.n1 - c w.n2) / (1 - c^2),    N2 = -(w.n2 - c w.n1) / (1 - c^2)

    (``w_perp.n_i = w.n_i`` because the line lies in both planes). For vertical gravity
    ``-w.n_i = cos(dip_i)`` and this is Hoek & Bray's ``N_a = W A sin(psi_i)``,
    ``A = (cos psi_a - cos psi_b cos theta_na.nb) / (sin psi_i sin^2 theta_na.nb)``.
    A negative ``N_i`` means the wedge would have to be pulled onto plane i: it lifts off.
    """
    n1, n2 = dip_normal(dip1, dd1), dip_normal(dip2, dd2)
    w = _unit_gravity(gravity)
    d = _line(n1, n2)
    wd = float(w @ d)
    driving = abs(wd)
    c = float(n1 @ n2)
    a, b = float(w @ n1), float(w @ n2)
    det = 1.0 - c * c
    return -(a - c * b) / det, -(b - c * a) / det, driving


def _planar(n: np.ndarray, w: np.ndarray, tan_phi: float) -> float:
    """Factor of safety of a block on one plane, sliding down its line of steepest descent
    (relative to gravity): ``tan(phi) N / S`` with ``N = -w.n``, ``S = |w - (w.n) n|``;
    for vertical gravity ``tan(phi) / tan(dip)``."""
    normal = max(0.0, -float(w @ n))
    shear = float(np.linalg.norm(w - (w @ n) * n))
    if shear <= _NO_DRIVE:
        return math.inf
    return tan_phi * normal / shear


def wedge_factor_of_safety(dip1: float, dd1: float, phi1: float, dip2: float, dd2: float, phi2: float,
                           gravity=(0.0, 0.0, -1.0)) -> tuple[float, str]:
    """Factor of safety ``(fs, mode)`` of a dry, cohesionless wedge on planes 1 and 2.

    The vector method of Hoek & Bray (1981, appendix 2) and Wyllie & Mah (2004, appendix III),
    with the normal reactions ``N1, N2`` (per unit weight) of :func:`normal_reactions`:

    * ``N1 > 0`` and ``N2 > 0``, mode ``"both"``: the wedge slides along the line of
      intersection, ``fs = (N1 tan(phi1) + N2 tan(phi2)) / (w.s)``; for vertical gravity the
      denominator is ``sin(psi_i)``, psi_i the plunge of the line. If the line is horizontal
      (relative to gravity), nothing drives the wedge: mode ``"stable"``, ``fs = inf``.
    * ``N2 <= 0 < N1``, mode ``"plane1"`` (or the other way round, ``"plane2"``): the wedge
      lifts off plane 2 and slides on plane 1 alone, down its line of steepest descent:
      ``fs = tan(phi1) (-w.n1) / |w - (w.n1) n1|``, i.e. ``tan(phi1) / tan(dip1)`` for
      vertical gravity.
    * both ``<= 0``, mode ``"free"``: the wedge loses contact with both planes and falls,
      ``fs = 0``.

    The mode depends on the geometry only, not on the friction angles, so for
    ``phi1 = phi2 = phi`` the factor of safety is ``K tan(phi)`` with a geometric factor K
    (Hoek & Bray's wedge factor over ``tan(psi_i)`` in mode ``"both"``).

    Friction angles in degrees in ``[0, 90)``. ``gravity`` needs only its direction (a bolt's
    force: :func:`bolted_wedge_factor_of_safety`). No cohesion or water pressure, and no
    daylighting test: a wedge whose
    line of intersection does not daylight in the slope face cannot slide whatever this says.
    """
    for phi in (phi1, phi2):
        if not (np.isfinite(phi) and 0.0 <= phi < 90.0):
            raise GeometryError(f"friction angle must be in [0, 90) degrees, got {phi}")
    t1, t2 = math.tan(math.radians(phi1)), math.tan(math.radians(phi2))
    r1, r2, driving = normal_reactions(dip1, dd1, dip2, dd2, gravity)
    if r1 <= 0.0 and r2 <= 0.0:
        return 0.0, "free"
    w = _unit_gravity(gravity)
    if r2 <= 0.0:
        fs = _planar(dip_normal(dip1, dd1), w, t1)
        return fs, ("plane1" if math.isfinite(fs) else "stable")
    if r1 <= 0.0:
        fs = _planar(dip_normal(dip2, dd2), w, t2)
        return fs, ("plane2" if math.isfinite(fs) else "stable")
    if driving <= _NO_DRIVE:
        return math.inf, "stable"
    return (r1 * t1 + r2 * t2) / driving, "both"


def critical_friction(dip1: float, dd1: float, dip2: float, dd2: float,
                      gravity=(0.0, 0.0, -1.0)) -> float:
    """Friction angle (degrees, the same on both planes) at which ``fs = 1``.

    Mode ``"both"``: ``tan(phi_c) = driving / (N1 + N2)`` (per unit weight, see
    :func:`normal_reactions`); modes ``"plane1"``/``"plane2"``: ``tan(phi_c) = S / N`` of the
    plane the wedge slides on, i.e. its dip for vertical gravity; ``"stable"``: 0 (the wedge
    needs no friction). A wedge that falls free (mode ``"free"``) is held by no friction
    angle: ``nan``.
    """
    r1, r2, driving = normal_reactions(dip1, dd1, dip2, dd2, gravity)
    if r1 <= 0.0 and r2 <= 0.0:
        return math.nan
    w = _unit_gravity(gravity)
    if r1 <= 0.0 or r2 <= 0.0:
        n = dip_normal(dip1, dd1) if r2 <= 0.0 else dip_normal(dip2, dd2)
        normal = max(0.0, -float(w @ n))
        shear = float(np.linalg.norm(w - (w @ n) * n))
        if shear <= _NO_DRIVE:
            return 0.0
        return math.degrees(math.atan2(shear, normal))
    if driving <= _NO_DRIVE:
        return 0.0
    return math.degrees(math.atan2(driving, r1 + r2))


def bolted_wedge_factor_of_safety(dip1: float, dd1: float, phi1: float, dip2: float, dd2: float,
                                  phi2: float, weight: float, force,
                                  gravity=(0.0, 0.0, -1.0)) -> tuple[float, str]:
    """:func:`wedge_factor_of_safety` of a wedge of weight ``weight`` (N) also loaded by a
    constant force ``force`` (N, a vector: a bolt's tension ``T u``, ``u`` the unit vector
    from the wedge towards the bolt's anchor in the rock behind).

    Without cohesion every force the planes carry scales with the load, so the wedge under
    ``P = weight g/|g| + force`` behaves as under a gravity along ``P``: the normal reactions
    (and so the mode) are those of ``P``, and the factor of safety, the factor by which
    ``tan(phi1)`` and ``tan(phi2)`` must both be divided for limit equilibrium (a
    strength-reduction search's), is ``(N1 tan phi1 + N2 tan phi2) / (P.s)`` with ``s`` along
    the line of intersection in ``P``'s sense (Hoek & Bray 1981, appendix 2, with the bolt's
    components in the resultant). A bolt that pulls the wedge against its weight enough to
    lift it off both planes gives mode ``"free"``; one that holds it against the driving
    component, ``"stable"``."""
    if not (np.isfinite(weight) and weight > 0.0):
        raise GeometryError(f"weight must be a finite positive force (N), got {weight!r}")
    f = np.asarray(force, dtype=float).reshape(3)
    if not np.all(np.isfinite(f)):
        raise GeometryError(f"force must be a finite vector (N), got {force!r}")
    p = weight * _unit_gravity(gravity) + f
    if float(np.linalg.norm(p)) <= _NO_DRIVE * weight:
        return math.inf, "stable"  # the bolt carries the weight: nothing left on the planes
    return wedge_factor_of_safety(dip1, dd1, phi1, dip2, dd2, phi2, gravity=p)
