"""Geometry priors: mass properties of a watertight mesh as a solid, a shell, or a 3D print.

All moments here are per unit density ([m^3], [m^4], [m^5]) in the mesh's frame,
so the mass properties of any fill are linear combinations of a few bodies:

    solid       the whole enclosed volume
    shell(t)    solid minus the inner body bounded by the surface offset inward by t [m]
    print(t, f) shell(t) plus a fraction f of the inner body (walls, top and bottom
                layers of thickness t, and a sparse infill of volume fraction f)

The inner body is exact for convex meshes (every face plane moved inward by t,
intersected) and, for any other watertight mesh, the level set at -t of its
signed distance on a grid (Open3D ray casting, scikit-image marching cubes).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from assets import Inertial
from assets.materials import MaterialRange


@dataclass(frozen=True)
class Prior:
    """theta0 and box bounds C in the object frame, with what they came from.

    lower/upper: (mass [kg], com xyz [m], Ixx Iyy Izz [kg m^2]). `uniform` is the
    uniform-density body (the mesh filled evenly) at theta0's mass, kept for later
    diagnosis of non-uniform objects. friction, friction_kinetic: (value, low, high),
    unitless, or None. structure: how the mesh was filled ("solid", "printed",
    "shell" or a mixture such as "printed+solid"). details: what the fusion did
    (geometry, VLM answer, distributions), JSON-serialisable.
    """

    inertial: Inertial
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    material: MaterialRange
    volume_m3: float
    uniform: Inertial
    friction: tuple[float, float, float] | None = None
    friction_kinetic: tuple[float, float, float] | None = None
    structure: str = "solid"
    details: dict = field(default_factory=dict)

    def provenance(self) -> dict:
        out = {
            "material": self.material.name,
            "density_kg_m3": [self.material.density_low, self.material.density, self.material.density_high],
            "source": self.material.source,
            "volume_m3": self.volume_m3,
            "lower": list(self.lower),
            "upper": list(self.upper),
            "structure": self.structure,
            **self.inertial.to_json(),
            "uniform": self.uniform.to_json(),
        }
        if self.friction is not None:
            out["friction_static"] = list(self.friction)
        if self.friction_kinetic is not None:
            out["friction_kinetic"] = list(self.friction_kinetic)
        return out | self.details


@dataclass(frozen=True)
class BodyMoments:
    """Mass moments per unit density, about the frame origin.

    volume [m^3]; first: integral of r dV [m^4], shape [3]; second: integral of r r^T dV
    [m^5], shape [3, 3]. Linear: bodies add and subtract, and scale with density.
    """

    volume: float
    first: np.ndarray
    second: np.ndarray

    @staticmethod
    def zero() -> "BodyMoments":
        return BodyMoments(0.0, np.zeros(3), np.zeros((3, 3)))

    def __add__(self, other: "BodyMoments") -> "BodyMoments":
        return BodyMoments(self.volume + other.volume, self.first + other.first, self.second + other.second)

    def __sub__(self, other: "BodyMoments") -> "BodyMoments":
        return self + other.scaled(-1.0)

    def scaled(self, k: float) -> "BodyMoments":
        return BodyMoments(k * self.volume, k * self.first, k * self.second)

    @property
    def com(self) -> np.ndarray:
        """Centre of volume [m], shape [3]."""
        return self.first / self.volume

    def unit_inertia(self) -> np.ndarray:
        """Inertia about the centre of volume per unit density [m^5], shape [3, 3]."""
        c = self.com
        S = self.second - self.volume * np.outer(c, c)
        return np.trace(S) * np.eye(3) - S

    def pseudo_inertia(self) -> np.ndarray:
        """The 4x4 pseudo-inertia per unit density about the frame origin, [[second, first], [first^T, volume]]
        [m^5, m^4, m^3]: a body of parts with densities rho_k has sum_k rho_k P_k (`pipelines.identify.posterior`)."""
        P = np.empty((4, 4))
        P[:3, :3] = self.second
        P[:3, 3] = P[3, :3] = self.first
        P[3, 3] = self.volume
        return P

    def inertial(self, density: float) -> Inertial:
        """The body at a uniform `density` [kg/m^3]."""
        return Inertial(density * self.volume, tuple(self.com), density * self.unit_inertia())


def moments_from_mesh(mesh) -> BodyMoments:
    """Moments of a closed, outward-oriented triangle mesh (trimesh) per unit density."""
    from trimesh.triangles import mass_properties

    props = mass_properties(np.asarray(mesh.triangles), density=1.0)
    volume = float(props["volume"])
    if volume <= 0:
        return BodyMoments.zero()
    c = np.asarray(props["center_mass"], dtype=float)
    I = np.asarray(props["inertia"], dtype=float)
    S_c = 0.5 * np.trace(I) * np.eye(3) - I
    return BodyMoments(volume, volume * c, S_c + volume * np.outer(c, c))


def solid_moments(mesh_object) -> BodyMoments:
    """Moments of the whole enclosed volume; ValueError for a mesh that is not a closed volume."""
    if not mesh_object.is_volume:
        raise ValueError("prior needs a watertight mesh with consistent normals")
    return moments_from_mesh(mesh_object)


def inner_moments(mesh_object, thicknesses_m, resolution: int = 48) -> list[BodyMoments]:
    """Moments of the inner bodies: the mesh offset inward by each thickness [m] (zero where none is left).

    Convex meshes are offset exactly; others through a signed-distance grid with
    `resolution` cells along the longest side (at least 16 along each), whose
    error is about a cell at edges and corners.
    """
    thicknesses_m = [float(t) for t in thicknesses_m]
    if any(t < 0 for t in thicknesses_m):
        raise ValueError(f"wall thicknesses must be >= 0 [m], got {thicknesses_m}")
    if mesh_object.is_convex:
        return [_convex_inner(mesh_object, t) for t in thicknesses_m]
    return _sdf_inner(mesh_object, thicknesses_m, resolution)


def shell_moments(solid: BodyMoments, inner: BodyMoments) -> BodyMoments:
    """A hollow body: walls between the surface and the inner body."""
    return solid - inner


def infill_moments(solid: BodyMoments, inner: BodyMoments, infill: float) -> BodyMoments:
    """A 3D print: walls (solid minus inner) plus a volume fraction `infill` (0..1) of the inner body."""
    if not 0.0 <= infill <= 1.0:
        raise ValueError(f"infill fraction must lie in [0, 1], got {infill}")
    return solid - inner.scaled(1.0 - infill)


def _convex_inner(mesh, t: float) -> BodyMoments:
    import trimesh
    from scipy.optimize import linprog
    from scipy.spatial import HalfspaceIntersection

    if t == 0.0:
        return moments_from_mesh(mesh)
    normals = np.asarray(mesh.face_normals, dtype=float)
    offsets = np.einsum("ij,ij->i", normals, np.asarray(mesh.triangles_center, dtype=float)) - t
    # Chebyshev centre: the deepest point, to start the halfspace intersection (and see if any is left).
    res = linprog(np.r_[np.zeros(3), -1.0], A_ub=np.c_[normals, np.ones(len(normals))], b_ub=offsets,
                  bounds=[(None, None)] * 3 + [(0, None)], method="highs")
    if not res.success or res.x[3] <= 1e-9 * max(mesh.extents):
        return BodyMoments.zero()
    points = HalfspaceIntersection(np.c_[normals, -offsets], res.x[:3]).intersections
    scale = float(max(mesh.extents))
    points = np.unique(np.round(points / (1e-9 * scale)), axis=0) * (1e-9 * scale)  # planes meeting at a vertex
    return moments_from_mesh(trimesh.convex.convex_hull(points))


def _sdf_inner(mesh, thicknesses_m: list[float], resolution: int) -> list[BodyMoments]:
    import open3d as o3d
    import trimesh
    from skimage.measure import marching_cubes

    lo, hi = np.asarray(mesh.bounds, dtype=float)
    extent = hi - lo
    cells = np.maximum(np.ceil(extent / (extent.max() / resolution)).astype(int), 16)
    step = extent / cells
    axes = [np.linspace(lo[i] - step[i], hi[i] + step[i], cells[i] + 3) for i in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(np.asarray(mesh.vertices, dtype=np.float32)),
                        o3d.core.Tensor(np.asarray(mesh.faces, dtype=np.uint32)))
    depth = -scene.compute_signed_distance(o3d.core.Tensor(grid.astype(np.float32))).numpy()  # > 0 inside
    depth = depth.reshape([len(a) for a in axes])
    out = []
    for t in thicknesses_m:
        if t == 0.0:
            out.append(moments_from_mesh(mesh))
            continue
        if depth.max() <= t:
            out.append(BodyMoments.zero())
            continue
        verts, faces, _, _ = marching_cubes(depth, level=t, spacing=tuple(float(a[1] - a[0]) for a in axes))
        inner = trimesh.Trimesh(verts + [a[0] for a in axes], faces, process=True)
        if inner.volume < 0:
            inner.invert()
        out.append(moments_from_mesh(inner))
    return out


def uniform_density_prior(mesh_object, material: MaterialRange, inertia_spread: tuple[float, float] = (0.3, 2.0)) -> Prior:
    """theta0 at the material's central density; C from its density range.

    mesh_object: watertight trimesh in the object frame (metres). The inertia
    bounds widen the uniform body's by `inertia_spread` for non-uniform fill
    (shells and heavy inserts move mass outwards or inwards).
    """
    if not mesh_object.is_volume:
        raise ValueError("prior needs a watertight mesh with consistent normals")
    volume = float(mesh_object.volume)
    mesh_object = mesh_object.copy()
    mesh_object.density = 1.0
    unit_inertia = np.asarray(mesh_object.moment_inertia)  # about the centroid, per unit density
    com = np.asarray(mesh_object.center_mass)
    uniform = Inertial(material.density * volume, com, material.density * unit_inertia)
    half = 0.5 * (mesh_object.bounds[1] - mesh_object.bounds[0])
    diag = np.diag(unit_inertia)
    lower = (material.density_low * volume, *(com - half), *(material.density_low * diag * inertia_spread[0]))
    upper = (material.density_high * volume, *(com + half), *(material.density_high * diag * inertia_spread[1]))
    friction = (material.friction, material.friction_low, material.friction_high)
    return Prior(uniform, tuple(map(float, lower)), tuple(map(float, upper)), material, volume, uniform,
                 friction=friction, friction_kinetic=material.kinetic())


def part_pseudo_inertias(meshes) -> np.ndarray:
    """Pseudo-inertias per unit density [K, 4, 4] of closed part meshes (the decomposition's convex parts, in the
    object frame), for per-part densities in the posterior; parts of no volume are left out."""
    out = [moments_from_mesh(m).pseudo_inertia() for m in meshes]
    return np.array([P for P in out if P[3, 3] > 0]).reshape(-1, 4, 4)
