"""The data model of a twin asset: frames, inertial parameters, estimates, the asset.

Everything is SI (metres, kilograms, seconds, radians) and expressed in the
object frame unless a name says otherwise. Quaternions are scalar-last
(x, y, z, w), as in scipy and Warp.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

Kind = Literal["free", "sliding", "prismatic", "revolute"]
KINDS: tuple[str, ...] = ("free", "sliding", "prismatic", "revolute")
Source = Literal["measured", "prior", "weighed"]


def _vec(values, length: int, name: str) -> tuple[float, ...]:
    arr = np.asarray(values, dtype=float).reshape(-1)
    if arr.shape != (length,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: expected {length} finite numbers, got {values!r}")
    return tuple(float(x) for x in arr)


def _mat3(values, name: str) -> tuple[tuple[float, ...], ...]:
    arr = np.asarray(values, dtype=float)
    if arr.shape != (3, 3) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: expected a finite 3x3 matrix, got shape {arr.shape}")
    return tuple(tuple(float(x) for x in row) for row in arr)


@dataclass(frozen=True)
class Pose:
    """A rigid transform: position [m] and unit quaternion (x, y, z, w)."""

    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    quaternion_xyzw: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)

    def __post_init__(self):
        object.__setattr__(self, "position", _vec(self.position, 3, "Pose.position"))
        q = np.asarray(_vec(self.quaternion_xyzw, 4, "Pose.quaternion_xyzw"))
        norm = np.linalg.norm(q)
        if not 0.9 < norm < 1.1:
            raise ValueError(f"Pose.quaternion_xyzw: not a unit quaternion (norm {norm:.4g})")
        object.__setattr__(self, "quaternion_xyzw", tuple(float(x) for x in q / norm))

    def rotation_matrix(self) -> np.ndarray:
        x, y, z, w = self.quaternion_xyzw
        return np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
            ]
        )

    def matrix(self) -> np.ndarray:
        """Homogeneous 4x4 transform."""
        T = np.eye(4)
        T[:3, :3] = self.rotation_matrix()
        T[:3, 3] = self.position
        return T

    @staticmethod
    def from_matrix(T: np.ndarray) -> "Pose":
        from scipy.spatial.transform import Rotation

        T = np.asarray(T, dtype=float)
        return Pose(tuple(T[:3, 3]), tuple(Rotation.from_matrix(T[:3, :3]).as_quat()))

    def inverse(self) -> "Pose":
        return Pose.from_matrix(np.linalg.inv(self.matrix()))

    def __matmul__(self, other: "Pose") -> "Pose":
        return Pose.from_matrix(self.matrix() @ other.matrix())

    def to_json(self) -> dict:
        return {"position": list(self.position), "quaternion_xyzw": list(self.quaternion_xyzw)}

    @staticmethod
    def from_json(d: dict) -> "Pose":
        return Pose(tuple(d["position"]), tuple(d["quaternion_xyzw"]))


@dataclass(frozen=True)
class Inertial:
    """Rigid-body inertial parameters in the object frame.

    mass [kg]; com [m], object frame; inertia [kg m^2], 3x3 about the COM,
    object-frame axes.
    """

    mass: float
    com: tuple[float, float, float]
    inertia: tuple[tuple[float, ...], ...]

    def __post_init__(self):
        if not (np.isfinite(self.mass) and self.mass > 0):
            raise ValueError(f"Inertial.mass: expected a positive mass [kg], got {self.mass!r}")
        object.__setattr__(self, "mass", float(self.mass))
        object.__setattr__(self, "com", _vec(self.com, 3, "Inertial.com"))
        I = np.asarray(_mat3(self.inertia, "Inertial.inertia"))
        object.__setattr__(self, "inertia", _mat3(0.5 * (I + I.T), "Inertial.inertia"))

    def inertia_matrix(self) -> np.ndarray:
        return np.array(self.inertia)

    def to_json(self) -> dict:
        return {"mass_kg": self.mass, "com_m": list(self.com), "inertia_kg_m2": [list(r) for r in self.inertia]}

    @staticmethod
    def from_json(d: dict) -> "Inertial":
        return Inertial(d["mass_kg"], tuple(d["com_m"]), d["inertia_kg_m2"])

    def principal(self) -> tuple[np.ndarray, np.ndarray]:
        """Principal moments (ascending) and a proper rotation R (det +1), I = R diag(d) R^T."""
        d, V = np.linalg.eigh(self.inertia_matrix())
        if np.linalg.det(V) < 0:
            V[:, 2] = -V[:, 2]
        return d, V

    def physical_violation(self) -> str | None:
        """None if positive definite and meeting the triangle inequality, else why not."""
        d, _ = self.principal()
        if d[0] <= 0:
            return f"inertia not positive definite (principal moments {d})"
        if d[0] + d[1] < d[2] * (1 - 1e-9):
            return f"inertia breaks the triangle inequality (principal moments {d})"
        return None


FLAT_INERTIAL: tuple[str, ...] = ("mass", "com_x", "com_y", "com_z", "Ixx", "Iyy", "Izz", "Ixy", "Ixz", "Iyz")
"""The flat inertial vector: mass [kg], COM [m] and the inertia about the COM [kg m^2], object frame. Covariances
and standard deviations of a body come in this order, and a prior's bounds C cover its first seven."""
MASS, COM, MOMENTS, PRODUCTS = 0, slice(1, 4), slice(4, 7), slice(7, 10)
"""Where each quantity sits in the flat vector; one moment by name: `FLAT_INERTIAL.index("Izz")`."""


def flat_inertial(body: Inertial) -> np.ndarray:
    """body as its flat vector (`FLAT_INERTIAL`)."""
    I = body.inertia_matrix()
    return np.array([body.mass, *body.com, I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]])


def symmetric_from_flat(flat) -> np.ndarray:
    """The 3x3 symmetric matrix whose diagonal and products sit at `MOMENTS` and `PRODUCTS` of a flat vector:
    the inertia of a flat body, or its standard deviations laid out as the tensor."""
    flat = np.asarray(flat, dtype=float)
    (xx, yy, zz), (xy, xz, yz) = flat[MOMENTS], flat[PRODUCTS]
    return np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])


@dataclass(frozen=True)
class Estimate:
    """An identified or prior quantity: value, standard deviation, where it came from.

    value/std are a float, a 3-vector or a 3x3 matrix (as nested tuples).
    `source` is "measured" when the data determined it, "prior" when it was
    taken from the prior because the data could not, "weighed" when it is the
    user's weighing (`--mass`) because the data could not determine it.
    """

    value: Any
    std: Any
    source: Source = "measured"
    interval95: Any = None
    prior: dict | None = None

    def to_json(self) -> dict:
        out: dict[str, Any] = {"value": _jsonable(self.value), "std": _jsonable(self.std), "source": self.source}
        if self.interval95 is not None:
            out["interval95"] = _jsonable(self.interval95)
        if self.prior is not None:
            out["prior"] = self.prior
        return out

    @staticmethod
    def from_json(d: dict) -> "Estimate":
        return Estimate(
            value=_tuplify(d["value"]),
            std=_tuplify(d.get("std")),
            source=d.get("source", "measured"),
            interval95=_tuplify(d.get("interval95")),
            prior=d.get("prior"),
        )


def _jsonable(x):
    if x is None:
        return None
    if isinstance(x, (np.ndarray, tuple, list)):
        return [_jsonable(v) for v in x]
    return float(x)


def _tuplify(x):
    if isinstance(x, list):
        return tuple(_tuplify(v) for v in x)
    return x


@dataclass(frozen=True)
class Theta:
    """The moving body's physical parameters (DESIGN.md `theta`)."""

    mass: Estimate
    com: Estimate
    inertia: Estimate
    friction: Estimate
    determined: tuple[tuple[str, Estimate], ...] = ()
    """Combinations a motion determines that are no theta field of their own (a door's
    inertia about its joint axis, an oven door's gravity moment m*d), by name."""

    def inertial(self) -> Inertial:
        return Inertial(self.mass.value, self.com.value, self.inertia.value)


@dataclass(frozen=True)
class Material:
    """A physical material: density [kg/m^3] and Coulomb friction (unitless)."""

    name: str
    density: float
    friction: float
    restitution: float = 0.0
    text: str | None = None
    """The user's words for it (`--material` or object.json's hint), as written."""
    source: str = "library"
    """How `name` was chosen: "named" (--material), "hint" (object.json matched), "unmatched" (a hint the
    library does not know: the wide `unknown` prior), "vlm", or "library" (no words given)."""
    match_score: float | None = None
    """How sure the match of `text` to `name` is, 0..1 (1: exact or a listed synonym)."""


@dataclass(frozen=True)
class Geometry:
    """Mesh files relative to the output directory, object frame, metres."""

    visual: str
    collision: tuple[str, ...]
    base: str | None = None
    """Jointed kinds: mesh of the fixed base, world frame (optional)."""
    extent: dict | None = None
    """How the closed solid was made from what the scan saw ("closing", "seen", "assumed" with the
    assumed sizes and their uncertainty): a part scanned in its furniture is extruded from its front by a
    thickness that may be assumed."""


@dataclass(frozen=True)
class Joint:
    """A joint of a jointed asset; axis and origin in the world frame."""

    type: Literal["prismatic", "revolute"]
    axis: tuple[float, float, float]
    origin: tuple[float, float, float]
    lower: float
    upper: float
    damping: float = 0.0
    stiffness: float = 0.0
    spring_ref: float = 0.0
    axis_std_rad: float | None = None
    """1-sigma angle of the axis direction's error, when estimated from motion [rad]."""
    origin_std_m: tuple[float, float, float] | None = None
    """1-sigma error of `origin` per world axis across the axis (revolute) [m]."""
    friction_grip_s: float | None = None
    """Time constant [s] with which the joint friction, within its bound, brings the joint to rest
    (q'' = -q' / friction_grip_s); None: not measured, a simulator's own default applies."""


@dataclass(frozen=True)
class Effect:
    """Physics found missing and added (DESIGN.md effect vocabulary)."""

    name: str
    params: dict
    evidence: dict = field(default_factory=dict)


@dataclass(frozen=True)
class FitMetrics:
    rmse_position_m: float
    rmse_rotation_rad: float
    loss: float


@dataclass(frozen=True)
class Fit:
    baseline: FitMetrics
    final: FitMetrics
    window_s: float


@dataclass(frozen=True)
class Asset:
    """One simulation-ready object, as recorded in asset.json."""

    name: str
    kind: Kind
    placement: Pose
    theta: Theta
    geometry: Geometry
    material: Material
    joint: Joint | None = None
    effects: tuple[Effect, ...] = ()
    fit: Fit | None = None
    unexplained: tuple[dict, ...] = ()
    flags: tuple[dict, ...] = ()
    """Warnings a user must see beside the numbers: {"parameter", "problem", ...} (a value outside its
    prior bounds, a parameter a mismatch may have corrupted)."""
    files: dict = field(default_factory=dict)
    provenance: dict = field(default_factory=dict)

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"Asset.kind: expected one of {KINDS}, got {self.kind!r}")
        if (self.joint is None) != (self.kind in ("free", "sliding")):
            raise ValueError(f"Asset.joint: kind {self.kind!r} {'needs' if self.joint is None else 'takes no'} joint")
