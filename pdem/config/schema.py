"""The scene file's schema: frozen pydantic models with every default filled in."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, Literal, Union

from pydantic import (
    Discriminator,
    Field,
    NonNegativeFloat,
    PositiveFloat,
    PositiveInt,
    PrivateAttr,
    Tag,
    ValidationError,
    field_validator,
    model_serializer,
    model_validator,
)
from pydantic.fields import FieldInfo
from pydantic_core import InitErrorDetails, PydanticCustomError

from ..contact.algorithms import ALGORITHMS
from ..contact.laws import JOINT_LAWS
from ..deformable.constitutive import ZONE_MODELS
from ..dynamics.damping import DAMPING
from ..registry import Registry
from ..strict import Strict
from . import records
from .sizes import parse_bytes
from .study import Study

# Hard bounds where double precision, not physics, ends (docs/limits.md): products of a few
# such numbers (a volume, an inertia, a kinetic energy) stay finite. A coordinate or length
# beyond a million km, a speed beyond 1000 km/s is a typo, and 1e308 made the geometry nan.
LENGTH_MAX = 1.0e9  # m
SPEED_MAX = 1.0e6  # m/s, rad/s
FORCE_MAX = 1.0e30  # N
Length = Annotated[float, Field(ge=-LENGTH_MAX, le=LENGTH_MAX)]
Speed = Annotated[float, Field(ge=-SPEED_MAX, le=SPEED_MAX)]
Force = Annotated[float, Field(ge=-FORCE_MAX, le=FORCE_MAX)]
Vec3 = tuple[Length, Length, Length]
Vec3Speed = tuple[Speed, Speed, Speed]
Vec3Force = tuple[Force, Force, Force]

# the scene keys a registry put among a model's fields (:func:`_follow_keys`), by model
_KEYED: dict[type, tuple[str, ...]] = {}


def _follow_keys(model: type[Strict], after: str | None, keyed: dict[str, FieldInfo]) -> None:
    """Put ``keyed`` (a registry's scene keys, in its order) among ``model``'s fields right
    after the field ``after`` (first when None), in place of the keys put there before, and
    rebuild the model's validator in place: the class, its messages and the other fields stay
    as declared. A key that is already another field of the model is refused."""
    old = _KEYED.get(model, ())
    fixed = [name for name in model.__pydantic_fields__ if name not in old]
    taken = sorted(set(keyed) & set(fixed))
    if taken:
        raise ValueError(f"{', '.join(map(repr, taken))}: already a key of {model.__name__}")
    fields = dict(keyed) if after is None else {}
    for name in fixed:
        fields[name] = model.__pydantic_fields__[name]
        if name == after:
            fields.update(keyed)
    model.__pydantic_fields__ = fields
    _KEYED[model] = tuple(keyed)
    model.model_rebuild(force=True)


Angle = Annotated[float, Field(ge=0.0, lt=90.0)]


class Material(Strict):
    """A block material: ``density`` alone for rigid blocks; with ``young`` and ``poisson``
    also the elasticity of deformable (``zones:``) blocks, and ``model`` the zone constitutive
    model (:data:`pdem.deformable.ZONE_MODELS`: ``elastic``, or ``mohr_coulomb`` with
    ``cohesion``, ``friction``, ``tension``, ``dilation``). Rigid blocks ignore the elastic
    keys."""

    density: PositiveFloat
    young: PositiveFloat | None = None
    poisson: Annotated[float, Field(gt=-1.0, lt=0.5)] | None = None
    model: str | None = None
    cohesion: NonNegativeFloat | None = None
    friction: Angle | None = None
    tension: NonNegativeFloat | None = None
    dilation: Angle | None = None

    @model_validator(mode="after")
    def _zone_model(self):
        """The elastic keys are checked by the zone model's own parameters (one message that
        names the key); the model name, with a did-you-mean, by the registry."""
        given = {k: v for k, v in self if v is not None and k != "density"}
        if not given:
            return self
        if self.young is None:
            raise ValueError(f"young: needed with {', '.join(sorted(given))} (the elasticity of "
                             "deformable blocks)")
        if self.poisson is None:
            raise ValueError("poisson: needed with young")
        try:
            model = ZONE_MODELS[self.model or "elastic"]
        except KeyError as exc:
            raise ValueError(f"model: {exc.args[0]}") from None
        try:
            model.params(density=self.density, **given)
        except ValidationError as exc:
            e = exc.errors()[0]
            key = ".".join(str(p) for p in e["loc"])
            text = e["msg"].removeprefix("Value error, ")
            if e["type"] == "extra_forbidden":
                text = f"not a parameter of the {model.name} model"
            raise ValueError(f"{key}: {text}" if key else text) from None
        return self

    @model_serializer(mode="wrap")
    def _drop_unset(self, handler):
        # a rigid material dumps as before the elastic keys existed (outputs, checkpoints)
        return {k: v for k, v in handler(self).items() if v is not None}

    @property
    def deformable(self) -> bool:
        """Has the elasticity a zoned block needs."""
        return self.young is not None

    def zone_spec(self) -> dict:
        """The zone model's parameters (``pdem.deformable.material``'s input)."""
        return {k: v for k, v in self if v is not None}


def joint_law_union():
    """The union of the registered joint laws' parameter models, told apart by ``model``
    (rebuilt into :class:`Scene` whenever a law is registered: :func:`_joint_laws_changed`)."""
    models = tuple(law.params for law in JOINT_LAWS.values())
    if len(models) == 1:
        return models[0]
    return Annotated[Union[models], Field(discriminator="model")]  # noqa: UP007


Joint = joint_law_union()


class JointPair(Strict):
    """Joint properties for contacts between a block of group ``groups[0]`` and one of
    ``groups[1]`` (order irrelevant)."""

    groups: tuple[str, str]
    joint: str


def _check_ordered(lo3, hi3) -> None:
    """``max`` exceeds ``min`` on every axis (a box, a domain)."""
    for axis, (lo, hi) in enumerate(zip(lo3, hi3, strict=True)):
        if not hi > lo:
            raise ValueError(f"max[{axis}] must exceed min[{axis}] ({hi} <= {lo})")


class BoxShape(Strict):
    min: Vec3
    max: Vec3

    @model_validator(mode="after")
    def _ordered(self):
        _check_ordered(self.min, self.max)
        return self


class PolyhedronShape(Strict):
    """Convex hull of ``vertices`` (every vertex must be on the hull), or, with ``faces``
    (vertex ids of each face, all counter-clockwise seen from outside or all clockwise), the
    closed polyhedron they bound, convex or not: a concave one becomes a joined block of convex
    pieces."""

    vertices: list[Vec3] = Field(min_length=4)
    faces: list[Annotated[list[Annotated[int, Field(ge=0)]], Field(min_length=3)]] | None = None


class PrismShape(Strict):
    """A convex planar polygon ``base`` swept along ``extrude``."""

    base: list[Vec3] = Field(min_length=3)
    extrude: Vec3


class PlanesShape(Strict):
    """Intersection of half-spaces ``normal . x <= offset``: the way joint planes cut rock."""

    normals: list[Vec3] = Field(min_length=4)
    offsets: list[Length] = Field(min_length=4)

    @model_validator(mode="after")
    def _same_length(self):
        if len(self.normals) != len(self.offsets):
            raise ValueError(
                f"normals and offsets differ in length ({len(self.normals)} vs {len(self.offsets)})"
            )
        return self


class MeshShape(Strict):
    """Blocks from a volume mesh (any format meshio reads): one convex block per 3D cell;
    cells sharing a value of the cell data ``cell_data_group`` are joined into one block
    named ``NAME[value]``. ``group_data``/``material_data``: cell data whose value (as text)
    is the block's group/material; ``select``: only cells whose cell data match (a value or
    a list of values per array)."""

    file: str
    cell_data_group: str | None = None
    group_data: str | None = None
    material_data: str | None = None
    select: dict[str, int | float | str | list[int | float | str]] | None = None


class ArrayOf(Strict):
    """Copies of a box on a regular lattice: ``count[i]`` copies spaced ``spacing[i]``."""

    box: BoxShape
    count: tuple[PositiveInt, PositiveInt, PositiveInt]
    spacing: Vec3


class RandomPolyhedra(Strict):
    """``count`` random convex polyhedra (hulls of ``vertices`` random points on a sphere of
    diameter in ``size``), one per lattice site of ``region``, reproducible from ``seed``."""

    count: PositiveInt
    region: BoxShape
    size: tuple[Annotated[float, Field(gt=0.0, le=LENGTH_MAX)],
                Annotated[float, Field(gt=0.0, le=LENGTH_MAX)]]
    vertices: Annotated[int, Field(ge=4, le=64)] = 10
    seed: int = 0


class Zones(Strict):
    """A deformable block: zoned into tetrahedra no longer than ``size`` (m) on any edge (a
    ``mesh`` block: its tetrahedral cells are the zones, no ``size``); ``nmd``: nodal mixed
    discretization (3DEC's default; off only to compare)."""

    size: Annotated[float, Field(gt=0.0, le=LENGTH_MAX)] | None = None
    nmd: bool = True


@dataclass(frozen=True)
class ShapeModel:
    """A block shape kind as the grammar knows it: ``model``, the pydantic model of its key
    (``blocks[i].<key>``), and whether a block of the kind may be ``zoned`` (today: one convex
    piece; the others are refused with why)."""

    model: type[Strict]
    zoned: bool = False


# The block shape kinds by scene key, in the order ``Block`` lists them: the grammar's own
# registry, which follows pdem.model.shapes.SHAPES (each kind there carries its model and
# builder: register a kind there); ``Block`` takes a field per entry, SHAPE_KEYS and
# ZONED_SHAPES are its names (:func:`_shapes_changed`).
SHAPE_MODELS: Registry[ShapeModel] = Registry("block shape")
for _key, _model, _zoned in (
    ("box", BoxShape, True), ("polyhedron", PolyhedronShape, True), ("prism", PrismShape, True),
    ("planes", PlanesShape, True), ("array", ArrayOf, True), ("random", RandomPolyhedra, True),
    ("mesh", MeshShape, True),
):
    SHAPE_MODELS.register(_key, ShapeModel(_model, _zoned))
SHAPE_KEYS = SHAPE_MODELS.names()
ZONED_SHAPES = tuple(k for k, s in SHAPE_MODELS.items() if s.zoned)


def _shape_fields() -> dict[str, FieldInfo]:
    for key, s in SHAPE_MODELS.items():
        if not (isinstance(s.model, type) and issubclass(s.model, Strict)):
            raise TypeError(f"block shape {key!r}: its model must be a pdem.strict.Strict "
                            "(a scene model)")
    return {key: FieldInfo.from_annotated_attribute(s.model | None, None)
            for key, s in SHAPE_MODELS.items()}


class Block(Strict):
    """One block (or, for ``array``/``random``, a family named ``name[i]``); its shape is
    the one key of a registered kind given (:data:`SHAPE_MODELS`, fields after ``name``)."""

    name: str
    material: str
    group: str = "default"
    fixed: bool = False
    velocity: Vec3Speed = (0.0, 0.0, 0.0)
    angular_velocity: Vec3Speed = (0.0, 0.0, 0.0)
    velocity_fixed: bool = False
    force: Vec3Force = (0.0, 0.0, 0.0)
    zones: Zones | None = None

    @model_validator(mode="after")
    def _one_shape(self):
        given = [k for k in SHAPE_KEYS if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError(
                "give exactly one shape of " + ", ".join(SHAPE_KEYS) + f" (got {given or 'none'})"
            )
        if self.zones is not None:
            kind = next(k for k in SHAPE_KEYS if getattr(self, k) is not None)
            if kind not in ZONED_SHAPES:
                raise ValueError(f"zones: not yet supported on {kind!r} blocks (a zoned block is "
                                 f"one convex {', '.join(ZONED_SHAPES)} shape)")
            if kind == "mesh" and self.zones.size is not None:
                raise ValueError("zones.size: a mesh block's zones are its tetrahedral cells as "
                                 "the mesh has them (remove size, or mesh it finer)")
            if kind != "mesh" and self.zones.size is None:
                raise ValueError("zones.size: Field required (the longest zone edge, m)")
            if self.velocity_fixed and any(self.angular_velocity):
                # a zoned block's prescribed motion is its gridpoints' fixed velocities, which
                # are constant: a rigid rotation would need them to turn with the block
                raise ValueError("velocity_fixed with angular_velocity: a zoned block's "
                                 "prescribed motion is a constant velocity of its gridpoints "
                                 "(give angular_velocity [0, 0, 0], or leave velocity_fixed "
                                 "off to start it spinning)")
        return self

    @model_serializer(mode="wrap")
    def _drop_rigid(self, handler):
        # a rigid block dumps as before ``zones`` existed (outputs, checkpoints)
        out = handler(self)
        if out.get("zones", 0) is None:
            del out["zones"]
        return out

    @property
    def shape_kind(self) -> str:
        return next(k for k in SHAPE_KEYS if getattr(self, k) is not None)


_follow_keys(Block, "name", _shape_fields())


class CutRange(Strict):
    """Which blocks a cut applies to: those whose centroid lies in ``box``."""

    box: BoxShape


class Cut(Strict):
    """A joint set (parallel planes) cutting the blocks, 3DEC's ``block cut joint-set``.
    x = east, y = north, z = up; ``dip`` below horizontal, ``dip_direction`` clockwise from
    north; ``origin`` lies on one plane; ``spacing`` between planes (omit: one plane);
    ``count`` planes on each side of ``origin`` (default: as many as cross the blocks)."""

    name: str
    dip: Annotated[float, Field(ge=0.0, le=90.0)]
    dip_direction: Annotated[float, Field(ge=-360.0, le=720.0)]
    origin: Vec3
    spacing: Annotated[float, Field(gt=0.0, le=LENGTH_MAX)] | None = None
    count: Annotated[int, Field(ge=0, le=1_000_000)] | None = None
    joint: str | None = None
    range: CutRange | None = None
    groups: list[str] | None = None

    @model_validator(mode="after")
    def _count_needs_spacing(self):
        if self.count and self.spacing is None:
            raise ValueError("count needs a spacing")
        return self


class CylinderRegion(Strict):
    """A polygonal cylinder (a tunnel): ``sides`` faces, corners on the circle of
    ``radius`` around the axis from ``start`` to ``end``."""

    start: Vec3
    end: Vec3
    radius: Annotated[float, Field(gt=0.0, le=LENGTH_MAX)]
    sides: Annotated[int, Field(ge=3, le=720)] = 24


class Excavation(Strict):
    """A convex region removed from the model (3DEC's ``block excavate``): blocks inside go,
    straddling blocks are cut by its surface and keep their outside as one (concave) block.
    ``time``: model time of the excavation (0: before the run starts); until then the inside
    pieces stay in the model as blocks of their own. ``groups``: only blocks of these groups."""

    cylinder: CylinderRegion | None = None
    box: BoxShape | None = None
    planes: PlanesShape | None = None
    time: Annotated[float, Field(ge=0.0)] = 0.0
    groups: list[str] | None = None

    @model_validator(mode="after")
    def _one_region(self):
        given = [k for k in REGION_KEYS if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError("give exactly one region of " + ", ".join(REGION_KEYS)
                             + f" (got {given or 'none'})")
        return self

    @property
    def region_kind(self) -> str:
        return next(k for k in REGION_KEYS if getattr(self, k) is not None)


REGION_KEYS = ("cylinder", "box", "planes")


class Timestep(Strict):
    """Automatic step ``frac * 2 sqrt(M_min / K_max)`` (eq. 87) unless ``dt`` is fixed."""

    frac: Annotated[float, Field(gt=0.0, le=1.0)] = 0.1
    dt: PositiveFloat | None = None


class MassScaling(Strict):
    """Partial (inertial) mass scaling to the step ``timestep`` (3DEC's ``mass-scale
    timestep``): the run steps at ``timestep``; only the blocks whose own critical step is
    below it get their mass and moments scaled up (one factor per block, docs/theory.md).
    Gravity and applied loads keep the true mass."""

    timestep: PositiveFloat


_FLAG, _MAPPING = "(true/false)", "({timestep: DT})"


def _mass_scaling_form(v) -> str:
    return _MAPPING if isinstance(v, dict | MassScaling) else _FLAG


# ``true``/``false`` (uniform scaling for static solves) or ``{timestep: DT}`` (partial).
# The tags carry a "(" so that error messages leave them out of the key path
# (pdem.config.load._clean_loc): "solve.mass_scaling.timestep: ...".
MassScalingSetting = Annotated[
    Union[Annotated[bool, Tag(_FLAG)], Annotated[MassScaling, Tag(_MAPPING)]],  # noqa: UP007
    Discriminator(_mass_scaling_form)]


def _names(registry) -> type:
    return Literal[registry.names()]


DampingMode = _names(DAMPING)


class Damping(Strict):
    """``alpha``: local/combined coefficient (eq. 79, default 0.8), viscous constant in 1/s
    (eq. 44), or the adaptive servo's starting constant. ``ratio``: adaptive target (eq. 77).
    ``rayleigh`` (dynamic analysis, docs/dynamics.md): ``fraction`` of critical damping at
    the centre ``frequency`` (Hz), its minimum (3DEC's form): mass-proportional constant
    ``alpha = fraction omega`` and stiffness-proportional ``beta = fraction / omega``,
    ``omega = 2 pi frequency``."""

    mode: DampingMode = "none"
    alpha: NonNegativeFloat | None = None
    ratio: Annotated[float, Field(gt=0.0, lt=1.0)] = 0.5
    fraction: Annotated[float, Field(gt=0.0, lt=1.0)] | None = None
    frequency: Annotated[float, Field(gt=0.0, le=1e6)] | None = None

    @model_validator(mode="after")
    def _rayleigh_keys(self):
        given = [k for k in ("fraction", "frequency") if getattr(self, k) is not None]
        if self.mode == "rayleigh":
            missing = [k for k in ("fraction", "frequency") if getattr(self, k) is None]
            if missing:
                raise ValueError(f"rayleigh damping needs {' and '.join(missing)} (the "
                                 "fraction of critical damping at a centre frequency in Hz)")
            if self.alpha is not None:
                raise ValueError("rayleigh damping takes fraction and frequency, not alpha")
        elif given:
            raise ValueError(f"{', '.join(given)}: only with mode: rayleigh")
        return self

    @property
    def rayleigh(self) -> tuple[float, float]:
        """``(alpha, beta)``: the mass- (1/s) and stiffness-proportional (s) constants; (0, 0)
        for every other mode."""
        if self.mode != "rayleigh":
            return 0.0, 0.0
        omega = 2.0 * math.pi * self.frequency
        return self.fraction * omega, self.fraction / omega


class Inactive(Strict):
    """Blocks at rest go inactive (docs/fidelity.md): a free block whose speed bound
    ``|v| + |w| r`` stays below ``speed`` and whose unbalanced force stays below ``force``
    times its weight for ``steps`` steps stops moving (its kinetic energy is booked as damping),
    and a contact between two inactive (or fixed) blocks keeps its forces without updating its
    joint. It wakes when its unbalanced force or moment (over its weight, times its radius)
    exceeds ``force`` again."""

    speed: PositiveFloat
    steps: PositiveInt = 100
    force: PositiveFloat = 0.01


# solve.no_progress_steps: the default window, and the smallest window other than 0 (off):
# the ratio is sampled 20 times a window (pdem.plugins.no_progress), so a window of a few
# hundred steps would judge a model by its first contact oscillations
NO_PROGRESS_STEPS = 20_000
NO_PROGRESS_MIN = 2_000
NoProgressSteps = Annotated[int, Field(ge=0)]


def _check_no_progress(v: int | None) -> int | None:
    if v is not None and 0 < v < NO_PROGRESS_MIN:
        raise ValueError(f"{v} steps is too short a window to judge a solve by (at least "
                         f"{NO_PROGRESS_MIN}, or 0: never stop for want of progress)")
    return v


class Solve(Strict):
    """The end condition (one of ``time``, ``steps``, ``ratio``) and the integration knobs.
    ``fused``: serial runs march many steps in one compiled call between Python-level events
    (pdem.cycle; bitwise the same result), off to time each phase of a step separately.
    ``energy_tolerance``: the run stops, naming the cause, when the energy balance error grows
    by more than this fraction of the energy put in between two budget samples (0: never).
    ``no_progress_steps``: a solve to a ``ratio`` stops, naming the blocks that keep it from
    its target and what they do, when its ratio has not improved for this many steps
    (pdem.plugins.no_progress; 0: never)."""

    time: PositiveFloat | None = None
    steps: PositiveInt | None = None
    ratio: PositiveFloat | None = None
    max_steps: PositiveInt | None = None
    no_progress_steps: NoProgressSteps = NO_PROGRESS_STEPS
    timestep: Timestep = Timestep()
    damping: Damping = Damping()
    mass_scaling: MassScalingSetting = False
    inertia: Literal["full", "scalar"] = "full"
    fused: bool = True
    inactive: Inactive | None = None
    progress_every: NonNegativeFloat = 2.0
    energy_tolerance: NonNegativeFloat = 0.1

    @field_validator("damping", mode="before")
    @classmethod
    def _damping_shorthand(cls, v):
        return {"mode": v} if isinstance(v, str) else v

    @field_validator("no_progress_steps")
    @classmethod
    def _no_progress_window(cls, v):
        return _check_no_progress(v)

    @model_validator(mode="after")
    def _one_end(self):
        # none is allowed here: a scene with stages ends each stage instead (Scene checks)
        ends = [k for k in ("time", "steps", "ratio") if getattr(self, k) is not None]
        if len(ends) > 1:
            raise ValueError(f"give exactly one of time, steps, ratio (got {ends})")
        if isinstance(self.mass_scaling, MassScaling) and self.timestep.dt is not None:
            raise ValueError("give timestep.dt or mass_scaling.timestep, not both (partial "
                             "mass scaling sets the step)")
        return self

    @property
    def has_end(self) -> bool:
        return any(getattr(self, k) is not None for k in ("time", "steps", "ratio"))


Stress = tuple[float, float, float, float, float, float]


class InSitu(Strict):
    """Initial stress of the rock mass (3DEC ``block insitu``): every joint starts with the
    forces of ``stress + gradient (z - reference_z)`` across its plane. Voigt order
    ``[sxx, syy, szz, sxy, syz, szx]``, Pa (gradient Pa/m), compression negative."""

    stress: Stress
    gradient: Stress = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    reference_z: Length = 0.0

    @model_validator(mode="after")
    def _bounded(self):
        for key in ("stress", "gradient"):
            if max(abs(v) for v in getattr(self, key)) > 1e15:
                raise ValueError(f"{key}: beyond 1e15 Pa (a typo?)")
        return self


class Selection(Strict):
    """Blocks by name (``NAME``, ``NAME[k]``, or a scene entry's name for all its blocks), by
    group, and/or by centroid in a box; the blocks matching every key given."""

    names: list[str] | None = None
    groups: list[str] | None = None
    range: CutRange | None = None

    @model_validator(mode="after")
    def _something(self):
        if self.names is None and self.groups is None and self.range is None:
            raise ValueError("give names, groups or range")
        return self


Component = Literal["x", "y", "z"]
Stress = Annotated[float, Field(ge=-FORCE_MAX, le=FORCE_MAX)]  # Pa; refuses nan and inf
TIME_MAX = 1.0e12  # s


class Harmonic(Strict):
    """``velocity = amplitude sin(2 pi frequency t + phase)``, ``phase`` in degrees."""

    amplitude: Vec3Speed
    frequency: Annotated[float, Field(ge=0.0, le=SPEED_MAX)]
    phase: Annotated[float, Field(ge=-3600.0, le=3600.0)] = 0.0


class VelocityHistory(Strict):
    """A time history of the prescribed velocity: exactly one of ``table``
    (``[[t, vx, vy, vz], ...]``, times strictly increasing; linear between rows, the first
    row's velocity before it and the last row's after it), ``harmonic``, or ``file``.
    Its time is the model time since the condition was applied (the run's start for
    ``boundary:``, the stage's start for a stage's ``velocity:``).

    ``file``: a history file (docs/dynamics.md "History files"; pdem.config.records): CSV
    (time, value) or PEER NGA ``.AT2``, read once here and resolved to a velocity table like
    ``table``'s (kept on the model, not in its dump: a restart reads the file again).
    ``quantity``: what its values are (``velocity`` m/s, ``acceleration`` m/s2 integrated
    from v = 0), times ``scale``, along ``direction`` (normalised); ``baseline``: subtract
    ``c1 t + c2 t^2`` so that velocity and displacement end at zero (default: true for an
    acceleration, false for a velocity)."""

    table: Annotated[list[tuple[Annotated[float, Field(ge=0.0, le=TIME_MAX)], Speed, Speed,
                                Speed]], Field(min_length=1)] | None = None
    harmonic: Harmonic | None = None
    file: Annotated[str, Field(min_length=1)] | None = None
    quantity: Literal["velocity", "acceleration"] = "velocity"
    direction: Vec3Speed | None = None
    scale: Speed = 1.0
    baseline: bool | None = None  # filled in with a file: true for an acceleration
    # the file resolved (pdem.config.records.VelocityRecord), or None
    _record = PrivateAttr(default=None)

    @model_validator(mode="before")
    @classmethod
    def _baseline_default(cls, data):
        if isinstance(data, dict) and data.get("file") is not None and "baseline" not in data:
            data = {**data, "baseline": data.get("quantity") == "acceleration"}
        return data

    @field_validator("table")
    @classmethod
    def _increasing(cls, v):
        for k in range(1, len(v or ())):
            if not v[k][0] > v[k - 1][0]:
                raise ValueError(f"times must increase strictly: row {k} (t = {v[k][0]:g}) "
                                 f"after t = {v[k - 1][0]:g}")
        return v

    @model_validator(mode="after")
    def _one(self):
        given = [k for k in ("table", "harmonic", "file") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError("give exactly one of table, harmonic, file"
                             + (f" (got {', '.join(given)})" if given else ""))
        if self.file is None:
            extra = [k for k in _FILE_KEYS if k in self.model_fields_set]
            if extra:
                raise self._at(extra, "only with file")
            return self
        if self.direction is None:
            raise self._at(["direction"], "needed with file (the values are along it)")
        if not any(self.direction):
            raise self._at(["direction"], "a zero vector has no direction")
        try:
            self._record = records.resolve(self.file, self.quantity, self.direction,
                                           self.scale, self.baseline)
        except records.RecordError as exc:
            raise self._at(["file"], str(exc)) from None
        return self

    def _at(self, keys: list[str], reason: str) -> ValidationError:
        """The error ``reason`` at each of ``keys`` (a ValidationError raised in a validator
        is placed under the model's location), so that the loader names ``history.file``
        and its line, not the whole history."""
        return ValidationError.from_exception_data(type(self).__name__, [InitErrorDetails(
            type=PydanticCustomError("history_file", "{reason}", {"reason": reason}),
            loc=(k,), input=self.model_dump()) for k in keys])

    @model_serializer(mode="wrap")
    def _drop_file_keys(self, handler):
        # a table or harmonic history dumps as before history files existed
        out = handler(self)
        if self.file is None:
            for k in ("file", *_FILE_KEYS):
                out.pop(k, None)
        return out

    @property
    def record(self) -> records.VelocityRecord | None:
        """The history file resolved to a velocity table (None for a table or harmonic)."""
        return self._record


_FILE_KEYS = ("quantity", "direction", "scale", "baseline")


class BoundaryVelocity(Selection):
    """Prescribed velocity of the selected blocks (3DEC's ``block fix`` with a velocity, or
    ``boundary xvel``... on a component): they move at it whatever the forces.

    ``components``: the translation components prescribed (default all three). With all three
    the whole motion is prescribed: ``velocity`` and ``angular_velocity``. With a subset only
    those components of the centroid velocity are prescribed; the other components and the
    rotation follow the forces (``angular_velocity`` must then be zero). ``history``: the
    velocity in time instead of the constant ``velocity`` (the components not prescribed are
    ignored)."""

    velocity: Vec3Speed = (0.0, 0.0, 0.0)
    angular_velocity: Vec3Speed = (0.0, 0.0, 0.0)
    components: Annotated[list[Component], Field(min_length=1, max_length=3)] = ["x", "y", "z"]
    history: VelocityHistory | None = None

    @model_validator(mode="after")
    def _consistent(self):
        if len(set(self.components)) != len(self.components):
            raise ValueError(f"components: repeated in {self.components}")
        if not self.all_components and any(self.angular_velocity):
            raise ValueError("angular_velocity: only with all components prescribed (a "
                             "partly prescribed block rotates freely)")
        if self.history is not None and any(self.velocity):
            raise ValueError("give velocity or history, not both")
        return self

    @property
    def all_components(self) -> bool:
        return len(self.components) == 3


StageVelocity = BoundaryVelocity  # a stage's prescribed velocities are the same conditions


class BoundaryStress(Selection):
    """A traction on the exposed faces of the selected blocks: ``pressure`` (Pa, positive
    pushes on the face) or ``tensor`` (Pa, world frame, ``[sxx, syy, szz, sxy, syz, szx]`` or
    a symmetric 3x3 list; compression negative, as in 3DEC). Face traction ``t = sigma n``
    (outward normal ``n``; a pressure is ``sigma = -p I``), applied as the force ``t A`` at
    the face centroid, which moves and turns with the block. ``wave``: instead, a wave put in
    through a quiet boundary (docs/dynamics.md): the traction ``2 rho (Cp (v.n) n + Cs (v -
    (v.n) n))`` of the history's particle velocity ``v`` (zoned blocks' faces)."""

    pressure: Stress | None = None
    tensor: tuple[Stress, Stress, Stress, Stress, Stress, Stress] | \
        tuple[tuple[Stress, Stress, Stress], tuple[Stress, Stress, Stress],
              tuple[Stress, Stress, Stress]] | None = None
    wave: VelocityHistory | None = None

    @model_validator(mode="after")
    def _one(self):
        if sum(v is not None for v in (self.pressure, self.tensor, self.wave)) != 1:
            raise ValueError("give exactly one of pressure, tensor, wave")
        if self.tensor is not None and isinstance(self.tensor[0], tuple):
            t = self.tensor
            for i, j in ((0, 1), (1, 2), (0, 2)):
                if t[i][j] != t[j][i]:
                    a, b = "xyz"[i], "xyz"[j]
                    raise ValueError(f"tensor: not symmetric (s{a}{b} = {t[i][j]:g}, "
                                     f"s{b}{a} = {t[j][i]:g})")
        return self

    def sigma(self):
        """The stress tensor as a 3x3 nested tuple (Pa; zero for a ``wave``)."""
        if self.wave is not None:
            return ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
        if self.pressure is not None:
            p = -self.pressure
            return ((p, 0.0, 0.0), (0.0, p, 0.0), (0.0, 0.0, p))
        t = self.tensor
        if isinstance(t[0], tuple):
            return t
        sxx, syy, szz, sxy, syz, szx = t
        return ((sxx, sxy, szx), (sxy, syy, syz), (szx, syz, szz))


class BoundaryQuiet(Selection):
    """A quiet (viscous) boundary on the exposed faces of the selected blocks (whose centroid
    lies in ``range``): Lysmer and Kuhlemeyer's dashpots ``rho Cp`` normal and ``rho Cs``
    shear per area, which absorb the waves that reach it (docs/dynamics.md).
    ``directions``: which of the two. ``release``: the static stage's support handed over to
    the dashpots (as 3DEC and FLAC3D do when a fixed boundary becomes quiet): every held
    degree of freedom of the gridpoints it takes is freed and keeps, from then on, the force
    that held it (its reaction when the condition is applied) as a constant load; a held
    rigid block whose faces it takes, its force and moment alike (pdem.boundary)."""

    directions: Annotated[list[Literal["normal", "shear"]],
                          Field(min_length=1, max_length=2)] = ["normal", "shear"]
    release: bool = False

    @field_validator("directions")
    @classmethod
    def _once(cls, v):
        if len(set(v)) != len(v):
            raise ValueError(f"repeated in {v}")
        return v


# The boundary-condition kinds' condition models by scene key (``boundary.<key>`` and a
# stage's ``<key>``: lists of conditions, each a Selection of the blocks it acts on), in the
# order the kinds apply: the grammar's own registry, which follows pdem.boundary.BOUNDARY_KINDS
# (each kind there carries its model and its hooks: register a kind there); BoundaryConditions
# and Stage take a list field per entry (:func:`_conditions_changed`).
CONDITION_MODELS: Registry[type[Selection]] = Registry("boundary condition")
CONDITION_MODELS.register("velocity", BoundaryVelocity)
CONDITION_MODELS.register("stress", BoundaryStress)
CONDITION_MODELS.register("quiet", BoundaryQuiet)


def _condition_fields() -> dict[str, FieldInfo]:
    for key, model in CONDITION_MODELS.items():
        if not (isinstance(model, type) and issubclass(model, Selection)):
            raise TypeError(f"boundary condition {key!r}: its condition model must be a "
                            "pdem.config.schema.Selection (the blocks it acts on)")
    return {key: FieldInfo.from_annotated_attribute(list[model], [])
            for key, model in CONDITION_MODELS.items()}


class BoundaryConditions(Strict):
    """Scene-level boundary conditions, in force from the start: prescribed velocities and
    boundary stresses (a stage may add more); a list field per registered kind
    (:data:`CONDITION_MODELS`)."""


_follow_keys(BoundaryConditions, None, _condition_fields())


class StageForce(Selection):
    """Constant force applied at the centroid of each selected block from this stage on
    (replaces its earlier applied force)."""

    force: Vec3Force


class StageSolve(Strict):
    """A stage's end condition (one of ``time`` (a duration), ``steps``, ``ratio``) and the
    knobs a stage may change (``no_progress_steps``: None for the scene's); the rest comes
    from the scene's ``solve``."""

    time: PositiveFloat | None = None
    steps: PositiveInt | None = None
    ratio: PositiveFloat | None = None
    max_steps: PositiveInt | None = None
    no_progress_steps: NoProgressSteps | None = None
    damping: Damping | None = None
    mass_scaling: MassScalingSetting | None = None

    @field_validator("damping", mode="before")
    @classmethod
    def _damping_shorthand(cls, v):
        return {"mode": v} if isinstance(v, str) else v

    @field_validator("no_progress_steps")
    @classmethod
    def _no_progress_window(cls, v):
        return _check_no_progress(v)

    @model_validator(mode="after")
    def _one_end(self):
        ends = [k for k in ("time", "steps", "ratio") if getattr(self, k) is not None]
        if len(ends) != 1:
            raise ValueError(f"give exactly one of time, steps, ratio (got {ends or 'none'})")
        return self


class FactorOfSafety(Strict):
    """Strength reduction: trial solves with tan(friction), cohesion and tension divided by F
    (of every joint, or of ``joints``), F bracketed by bisection between 1 (must be stable)
    and ``high`` to ``tolerance`` (relative); with ``low`` a model unstable at F = 1 is
    searched between ``low`` and 1 instead (F < 1: the strength raised). A trial is stable
    when the unbalanced-force ratio falls below ``ratio`` within ``max_steps`` and unstable
    when it does not (or a block moves more than ``max_displacement``, m)."""

    tolerance: Annotated[float, Field(gt=0.0, lt=1.0)] = 0.01
    high: Annotated[float, Field(gt=1.0, le=1e3)] = 4.0
    low: Annotated[float, Field(gt=0.0, lt=1.0)] | None = None
    ratio: PositiveFloat = 1e-4
    max_steps: PositiveInt = 20_000
    max_displacement: PositiveFloat | None = None
    joints: list[str] | None = None


class Grout(Strict):
    """The grout annulus of a cable or bolt, per metre of its length: its shear stiffness
    (N/m per m) and strength (N per m; 0: unbonded, the element slides freely in its hole).
    Across the element the grout holds it to the rock with the same stiffness and no limit."""

    stiffness: PositiveFloat
    strength: NonNegativeFloat


class TunnelPattern(Strict):
    """Rings of radial bolts along a tunnel's axis, from ``start`` to ``end`` (m), every
    ``spacing`` m, ``per_ring`` bolts of ``length`` m each starting on the wall at
    ``radius``; ``arc`` (degrees, measured from the crown towards the right hand looking from
    start to end) is the part of the ring they cover, spaced evenly, both ends included
    unless it is the whole ring."""

    start: Vec3
    end: Vec3
    radius: PositiveFloat
    spacing: PositiveFloat
    per_ring: PositiveInt
    length: PositiveFloat
    arc: tuple[float, float] = (0.0, 360.0)


class ReinforcementPattern(Strict):
    tunnel: TunnelPattern


class Reinforcement(Strict):
    """Structural elements of 3DEC's kind: ``cable`` (nodes with lumped mass, axial springs
    ``EA/L`` yielding at ``yield_tension``/``yield_compression`` (N, 0: no yield), a grout
    spring and strength per metre between each node and the rock it lies in) and
    ``rockbolt`` (a cable that also resists shear where it crosses a joint: ``shear_stiffness``
    N/m, ``shear_strength`` N (0: no limit), and breaks at ``failure_strain`` (0: never)).
    One straight element ``from``/``to``, or a ``pattern`` of them; ``anchors`` names the
    ends held to their rock without slip (a mechanical anchor, a face plate)."""

    name: str
    model: Literal["cable", "rockbolt"] = "cable"
    from_: Vec3 | None = Field(None, alias="from")
    to: Vec3 | None = None
    pattern: ReinforcementPattern | None = None
    segments: PositiveInt = 8
    young: PositiveFloat
    area: PositiveFloat
    density: PositiveFloat = 7850.0
    yield_tension: NonNegativeFloat = 0.0
    yield_compression: NonNegativeFloat = 0.0
    grout: Grout | None = None
    pretension: NonNegativeFloat = 0.0
    anchors: list[Literal["from", "to"]] = []
    shear_stiffness: PositiveFloat | None = None
    shear_strength: NonNegativeFloat = 0.0
    failure_strain: NonNegativeFloat = 0.0

    @model_validator(mode="after")
    def _one_layout(self):
        line = self.from_ is not None or self.to is not None
        if line == (self.pattern is not None):
            raise ValueError("give either from and to, or a pattern")
        if line and (self.from_ is None or self.to is None):
            raise ValueError("give both from and to")
        if line and math.dist(self.from_, self.to) == 0.0:
            raise ValueError("from and to are the same point")
        if self.model == "cable" and (self.shear_stiffness is not None or self.failure_strain
                                      or self.shear_strength):
            raise ValueError("shear_stiffness, shear_strength and failure_strain are a "
                             "rockbolt's (model: rockbolt)")
        if self.model == "rockbolt" and self.shear_stiffness is None:
            raise ValueError("a rockbolt needs its shear_stiffness (N/m) at joint crossings")
        if self.pretension and self.yield_tension and self.pretension >= self.yield_tension:
            raise ValueError(f"pretension {self.pretension:g} N is not below yield_tension "
                             f"{self.yield_tension:g} N")
        return self


class Stage(Strict):
    """One stage of a staged run: model changes, then a solve (or a factor-of-safety search).
    Excavations are cut when the model is built and removed when the stage starts."""

    name: str
    excavate: list[Excavation] = []
    joints: dict[str, dict[str, float]] = {}
    fix: Selection | None = None
    free: Selection | None = None
    # here: a list field per boundary-condition kind (CONDITION_MODELS: velocity, stress, ...)
    force: list[StageForce] = []
    reinforce: list[str] = []
    reset_displacements: bool = False
    solve: StageSolve | None = None
    factor_of_safety: FactorOfSafety | None = None

    @model_validator(mode="after")
    def _one_action(self):
        if (self.solve is None) == (self.factor_of_safety is None):
            raise ValueError("give exactly one of solve, factor_of_safety")
        for e in self.excavate:
            if e.time != 0.0:
                raise ValueError("a stage's excavations happen when it starts: no time")
        return self


_follow_keys(Stage, "free", _condition_fields())


class Contact(Strict):
    """Accuracy/speed knobs of contact detection. ``ctol`` (CTOL, m): contacts exist while the
    gap is at most ctol; ``auto`` = 2% of the smallest block's equivalent size. ``cell_size``:
    cell-space cell edge, ``auto`` = the mean block envelope size (about one cell per block)."""

    ctol: PositiveFloat | Literal["auto"] = "auto"
    cell_size: PositiveFloat | Literal["auto"] = "auto"
    detect_every: PositiveInt = 10
    refresh_tolerance: NonNegativeFloat = 0.01
    algorithm: _names(ALGORITHMS) = "fast"
    point_area: NonNegativeFloat = 0.01
    overlap_tolerance: PositiveFloat | Literal["auto"] = "auto"


class Parallel(Strict):
    """Domain decomposition (docs/parallel.md). ``balance``: ``uniform`` = a grid of ranks
    splitting the model's box at start into equal bricks, fixed for the run; ``rcb`` =
    recursive coordinate bisection of the blocks weighted by their contacts, recomputed when
    the work is imbalanced; ``auto`` = ``rcb``, or ``uniform`` if ``dims`` is given. ``dims``
    (uniform): ranks per axis (product = number of ranks), ``auto`` = MPI's factorisation with
    the largest factor on the longest axis, gravity's axis last. ``rebalance`` (rcb): the
    imbalance (max / mean of the ranks' owned work) above which a rebuild recomputes the cuts;
    null = keep the start's cuts. ``margin`` (m): how far beyond its blocks a rank keeps
    ghosts; blocks moving half of it trigger a rebuild (migration + ghost lists). ``auto`` =
    the cell size."""

    balance: Literal["auto", "uniform", "rcb"] = "auto"
    dims: tuple[PositiveInt, PositiveInt, PositiveInt] | Literal["auto"] = "auto"
    rebalance: Annotated[float, Field(gt=1.0, le=1.0e6)] | None = 1.2
    margin: PositiveFloat | Literal["auto"] = "auto"

    @model_validator(mode="after")
    def _grid_or_rcb(self):
        if self.balance == "rcb" and self.dims != "auto":
            raise ValueError(f"dims {list(self.dims)} is a rank grid, for balance: uniform; "
                             "balance: rcb places its own cuts: give one of dims, balance: rcb")
        return self


class History(Strict):
    """Record ``quantity`` of block ``block`` every ``every`` model seconds (or every step),
    or at a recording station ``point``: the zoned blocks' gridpoint nearest to it (on their
    reference positions) where a zoned block's box holds it, else the rigid block whose
    centroid is nearest (docs/dynamics.md). ``acceleration``: the velocity's change over the
    step before the sample, over the step."""

    block: str | None = None
    point: Vec3 | None = None
    quantity: Literal["displacement", "velocity", "position", "angular_velocity",
                      "acceleration"]
    every: PositiveFloat | None = None

    @model_validator(mode="after")
    def _one(self):
        if (self.block is None) == (self.point is None):
            raise ValueError("give exactly one of block, point")
        if self.point is not None and self.quantity == "angular_velocity":
            raise ValueError("angular_velocity: of a block (a station records a point's "
                             "motion)")
        return self


# The zoned blocks' series a scene may choose (pdem.io.zones.ZONE_FIELDS, the same names in
# the same order: tests/unit/test_zone_output.py); the gridpoint positions are always written.
ZONE_FIELDS = ("displacement", "velocity", "stress", "plastic", "mean_stress", "von_mises",
               "sigma1", "sigma2", "sigma3")
ZoneField = Literal[ZONE_FIELDS]


class ZoneOutput(Strict):
    """``fields``: the zoned blocks' series each snapshot writes besides the gridpoint
    positions (docs/output.md, Zoned blocks); default all of them."""

    fields: list[ZoneField] = list(ZONE_FIELDS)

    @field_validator("fields")
    @classmethod
    def _once(cls, v):
        twice = sorted({f for f in v if v.count(f) > 1})
        if twice:
            raise ValueError(f"{', '.join(twice)} given more than once")
        return v


class Output(Strict):
    """``energy_every``: steps between energy-budget samples (``histories/energy``); default
    ten per snapshot interval. ``contacts``: store the joint state (every contact and
    sub-contact, their forces and states) with each snapshot (docs/output.md, Contacts).
    ``zones``: what the zoned blocks write (:class:`ZoneOutput`)."""

    file: str = "pdem-out.h5"
    contacts: bool = True
    every: PositiveFloat | None = None
    every_steps: PositiveInt | None = None
    energy_every: PositiveInt | None = None
    histories: list[History] = []
    zones: ZoneOutput = ZoneOutput()

    @model_serializer(mode="wrap")
    def _drop_default_zones(self, handler):
        # a scene that keeps the default dumps as before output.zones existed (outputs,
        # checkpoints): the dump reads back the same
        out = handler(self)
        if out.get("zones") == {"fields": list(ZONE_FIELDS)}:
            del out["zones"]
        return out

    @model_validator(mode="after")
    def _one_interval(self):
        if self.every is not None and self.every_steps is not None:
            raise ValueError("give at most one of every, every_steps")
        return self


class Checkpoint(Strict):
    """Full-state checkpoints every ``every`` model seconds (or ``every_steps``), named
    ``{file}-{step:09d}.h5``; the newest ``keep`` are kept. Restart: ``pdem restart FILE``."""

    every: PositiveFloat | None = None
    every_steps: PositiveInt | None = None
    keep: PositiveInt = 2
    file: str = "checkpoint"

    @model_validator(mode="after")
    def _one_interval(self):
        if (self.every is None) == (self.every_steps is None):
            raise ValueError("give exactly one of every, every_steps")
        return self


class Domain(Strict):
    """The model domain (3DEC's): a free block whose centroid leaves the box is taken out of
    the model, ``delete``d (no more contacts or motion; its last pose stays in the output) or
    ``freeze``d (it stops where it is and acts as a fixed block)."""

    min: Vec3
    max: Vec3
    action: Literal["delete", "freeze"] = "delete"

    @model_validator(mode="after")
    def _ordered(self):
        _check_ordered(self.min, self.max)
        return self


class Limits(Strict):
    """What a scene may ask of the machine, checked before anything is built (pdem.config.
    preflight, docs/limits.md). ``max_blocks``: blocks after expanding ``array``/``random``;
    ``auto`` = what fits in ``max_memory_per_rank``. ``max_memory_per_rank``: bytes (a number
    or text like ``8 GiB``); ``auto`` = 0.85 of this machine's memory shared by the ranks.
    ``max_steps``: the steps a run's end may imply (``solve.time`` / dt, ``solve.steps``).
    ``max_snapshots``: the snapshots one output file may hold: a scene whose end and
    ``output.every`` imply more is refused; a solve to a ratio stops its periodic snapshots
    there (pdem.plugins.output; null: no bound)."""

    max_blocks: PositiveInt | Literal["auto"] = "auto"
    max_memory_per_rank: PositiveFloat | str = "auto"
    max_steps: PositiveInt = 1_000_000_000
    max_snapshots: PositiveInt | None = 10_000

    @field_validator("max_memory_per_rank")
    @classmethod
    def _size(cls, v):
        if v != "auto":
            parse_bytes(v)
        return v


class Scene(Strict):
    # YAML line of each key path, set by pdem.config.load (empty for scenes built in code)
    _lines: dict = PrivateAttr(default_factory=dict)

    name: str = "pdem"
    gravity: Vec3Speed = (0.0, 0.0, -9.81)  # m/s2, bounded like a speed
    materials: dict[str, Material] = Field(min_length=1)
    joints: dict[str, Joint] = Field(min_length=1)
    joint_pairs: list[JointPair] = []
    blocks: list[Block] = Field(min_length=1)
    cuts: list[Cut] = []
    cut_tolerance: Annotated[float, Field(ge=0.0, le=LENGTH_MAX)] | Literal["auto"] = "auto"
    join_slivers: Annotated[float, Field(ge=0.0, lt=1.0)] = 0.05
    join: list[Annotated[list[str], Field(min_length=2)]] = []
    excavate: list[Excavation] = []
    stages: list[Stage] = []
    reinforcement: list[Reinforcement] = []
    studies: dict[str, Study] = {}
    insitu: InSitu | None = None
    boundary: BoundaryConditions = BoundaryConditions()
    contact: Contact = Contact()
    parallel: Parallel = Parallel()
    solve: Solve
    output: Output = Output()
    checkpoint: Checkpoint | None = None
    domain: Domain | None = None
    limits: Limits = Limits()

    def __eq__(self, other) -> bool:
        # the values, not where they came from (``_lines``)
        return isinstance(other, Scene) and self.__dict__ == other.__dict__

    __hash__ = None  # a scene holds dicts: unhashable, as before

    def at(self, *path) -> str:
        """``path`` as a key path (``cuts[2].dip``) with its YAML line when known."""
        text = ""
        for part in path:
            text += f"[{part}]" if isinstance(part, int) else ("." if text else "") + str(part)
        line = self._lines.get(tuple(path))
        return f"{text} (line {line})" if line else text

    @field_validator("joints", mode="before")
    @classmethod
    def _default_law(cls, v):
        # ``model`` may be omitted: Coulomb slip, as in 3DEC
        if isinstance(v, dict):
            return {k: ({"model": "coulomb", **j} if isinstance(j, dict) and "model" not in j
                        else j) for k, j in v.items()}
        return v

    @model_validator(mode="after")
    def _references(self):
        """Names that must exist; each message names the referring key."""
        errors: list[str] = []
        names: dict[str, int] = {}
        for i, b in enumerate(self.blocks):
            if b.material not in self.materials:
                errors.append(
                    f"blocks[{i}].material: unknown material {b.material!r} "
                    f"(defined: {', '.join(sorted(self.materials))})"
                )
            if b.name in names:
                errors.append(f"blocks[{i}].name: {b.name!r} already names blocks[{names[b.name]}]")
            names[b.name] = i
            if b.zones is not None and b.material in self.materials:
                if not self.materials[b.material].deformable:
                    errors.append(f"blocks[{i}].zones: material {b.material!r} has no young and "
                                  "poisson (a zoned block needs its elasticity)")
        if "default" not in self.joints and not self.joint_pairs:
            errors.append("joints: define a joint named 'default' (used by every contact)")
        groups = {b.group for b in self.blocks}
        # groups read from mesh cell data are known once the mesh is read (pdem.model.build)
        open_groups = any(b.mesh is not None and b.mesh.group_data for b in self.blocks)
        for i, jp in enumerate(self.joint_pairs):
            if jp.joint not in self.joints:
                errors.append(f"joint_pairs[{i}].joint: unknown joint {jp.joint!r}")
            for g in jp.groups:
                if g not in groups and not open_groups:
                    errors.append(
                        f"joint_pairs[{i}].groups: no block has group {g!r} "
                        f"(groups: {', '.join(sorted(groups))})"
                    )
        if not self.stages and not self.solve.has_end:
            errors.append("solve: give exactly one of time, steps, ratio (got none), or stages")
        names_seen = set()
        for i, st in enumerate(self.stages):
            if st.name in names_seen:
                errors.append(f"stages[{i}].name: {st.name!r} names an earlier stage")
            names_seen.add(st.name)
            for k, changes in st.joints.items():
                if k not in self.joints:
                    errors.append(f"stages[{i}].joints: unknown joint {k!r} "
                                  f"(defined: {', '.join(sorted(self.joints))})")
                    continue
                fields = [f for f in type(self.joints[k]).model_fields if f != "model"]
                for key in changes:
                    if key not in fields:
                        errors.append(f"stages[{i}].joints.{k}.{key}: not a parameter of its "
                                      f"{self.joints[k].model} joint ({', '.join(fields)})")
            for key in ("fix", "free"):
                sel = getattr(st, key)
                for g in (sel.groups or ()) if sel else ():
                    if g not in groups and not open_groups:
                        errors.append(f"stages[{i}].{key}.groups: no block has group {g!r}")
            for key in (*CONDITION_MODELS, "force"):
                for j, sel in enumerate(getattr(st, key)):
                    for g in sel.groups or ():
                        if g not in groups and not open_groups:
                            errors.append(f"stages[{i}].{key}[{j}].groups: no block has "
                                          f"group {g!r} (groups: {', '.join(sorted(groups))})")
            fos = st.factor_of_safety
            for j in (fos.joints or ()) if fos else ():
                if j not in self.joints:
                    errors.append(f"stages[{i}].factor_of_safety.joints: unknown joint {j!r}")
        known, installed = {}, {}
        for i, r in enumerate(self.reinforcement):
            if r.name in known:
                errors.append(f"reinforcement[{i}].name: {r.name!r} is reinforcement[{known[r.name]}]'s")
            known.setdefault(r.name, i)
        for i, st in enumerate(self.stages):
            for j, name in enumerate(st.reinforce):
                if name not in known:
                    errors.append(f"stages[{i}].reinforce[{j}]: unknown reinforcement {name!r} "
                                  f"(defined: {', '.join(known) or 'none'})")
                elif name in installed:
                    errors.append(f"stages[{i}].reinforce[{j}]: {name!r} is installed by "
                                  f"stages[{installed[name]}] already")
                installed.setdefault(name, i)
        for key in CONDITION_MODELS:
            for j, sel in enumerate(getattr(self.boundary, key)):
                for g in sel.groups or ():
                    if g not in groups and not open_groups:
                        errors.append(f"boundary.{key}[{j}].groups: no block has group {g!r} "
                                      f"(groups: {', '.join(sorted(groups))})")
        for i, c in enumerate(self.cuts):
            if c.joint is not None and c.joint not in self.joints:
                errors.append(f"cuts[{i}].joint: unknown joint {c.joint!r} "
                              f"(defined: {', '.join(sorted(self.joints))})")
            for g in c.groups or ():
                if g not in groups and not open_groups:
                    errors.append(f"cuts[{i}].groups: no block has group {g!r} "
                                  f"(groups: {', '.join(sorted(groups))})")
        for i, h in enumerate(self.output.histories):
            if h.block is not None and h.block not in names and not _is_family_member(h.block, names):
                errors.append(f"output.histories[{i}].block: unknown block {h.block!r}")
        if errors:
            raise ValueError("\n".join(errors))
        return self


def _is_family_member(name: str, names: dict[str, int]) -> bool:
    """``stack[12]`` refers to the 13th block generated by the entry named ``stack``."""
    if not name.endswith("]") or "[" not in name:
        return False
    return name[: name.index("[")] in names


def _joint_laws_changed() -> None:
    """A joint law was registered (or removed): ``joints:`` takes the registered laws' union
    from now on, so a law added from outside pdem's tree is selected by ``model:`` in a scene
    like a shipped one (pydantic rebuilds the model's validator around the new annotation)."""
    Scene.model_fields["joints"].annotation = dict[str, joint_law_union()]
    Scene.model_rebuild(force=True)


JOINT_LAWS.watch(_joint_laws_changed)


def _conditions_changed() -> None:
    """A boundary-condition kind was registered (or removed): ``boundary:`` and every stage
    take a list field per registered kind from now on, in the registry's order (the shipped
    keys where they always were), and ``boundary:``'s default has them all empty."""
    _follow_keys(BoundaryConditions, None, _condition_fields())
    _follow_keys(Stage, "free", _condition_fields())
    Scene.model_fields["boundary"].default = BoundaryConditions()
    Scene.model_rebuild(force=True)


def _shapes_changed() -> None:
    """A block shape kind was registered (or removed): ``Block`` takes a field per kind after
    ``name``, and SHAPE_KEYS/ZONED_SHAPES name the kinds, from now on."""
    global SHAPE_KEYS, ZONED_SHAPES
    _follow_keys(Block, "name", _shape_fields())
    SHAPE_KEYS = SHAPE_MODELS.names()
    ZONED_SHAPES = tuple(k for k, s in SHAPE_MODELS.items() if s.zoned)
    Scene.model_rebuild(force=True)


CONDITION_MODELS.watch(_conditions_changed)
SHAPE_MODELS.watch(_shapes_changed)
