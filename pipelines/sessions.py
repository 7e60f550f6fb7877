"""Several scan sessions of one object (as it rests, then turned over or on its side) merged into one mesh.

One session cannot see under the parts of an object raised off the table (a
wrench's handle, a caliper's beam), and closing against the support plane fills
that space: +8 to +29 % of volume on the workshop tools. Closing only ever adds
volume in space the session never saw, so each session's solid is an outer
bound of the object, and the intersection of sessions scanned in different
resting poses removes what any of them saw to be empty.

Method:

1. Reconstruct each session alone, silhouette pixels left out of the fusion
   (`SessionsConfig.reconstruct`).
2. Observed surface: the vertices of each mesh within the observed points'
   spacing of the points segmented as the object (what its cameras saw), away
   from the support plane and not facing it; the closed-off part and the
   undersides seen only through a gap are left out.
3. Register each later session to the first. Objective, in both directions
   (later in first, first in later): where the other solid's surface was
   observed and faces the same way, an observed point lies on it (its signed
   distance); anywhere else it lies inside that solid (the positive part of the
   signed distance), except within the other's cut band, where that solid is
   an extrusion rather than a bound. The two directions together pin the pose
   even when the sessions saw little surface in common (a flat tool turned over
   shares only its rim). Each session's object rested on its support plane, so
   that plane, carried into the other's world, touches the other's observed
   surface where the object stood (a face of its convex hull, taken on that
   surface smoothed over the depth noise so that noise bumps do not stand in
   for the contact): those contacts are held on it, which pins a flat tool's
   pitch. Starts: the four proper alignments of the solids' principal axes,
   plus seeded random rotations when two principal moments are close; each
   refined briefly (Levenberg-Marquardt, soft-L1 loss) on a subsample, the
   best ones refined on more points. When several distinct poses fit about
   equally well (a symmetric object turned over looks the same either way),
   every one keeps the object inside both solids, so the one whose
   intersection is smallest is kept: it carves what either session saw empty.
4. Check: fitness is the smaller, over the two directions, of the fraction of
   observed points within `inlier_distance_m` of, or inside, the other solid;
   RMSE is over the points where both sessions saw the surface. Fitness below
   `min_fitness` raises `SessionError` naming the session.
5. Intersect the solids (manifold3d through trimesh), keep the largest piece,
   simplify to the reconstruction's face budget.

The first session defines the world (its support plane, its placement): the
merged mesh is where the object lay in the first session.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Sequence

import numpy as np

from .reconstruct import ReconstructConfig, ReconstructError, Reconstruction, reconstruct, simplify_watertight
from .rgbd import Scan

if TYPE_CHECKING:
    import trimesh

__all__ = ["Registration", "SessionError", "SessionsConfig", "merge_reconstructions", "merge_sessions",
           "register_session"]


class SessionError(ReconstructError):
    """A later scan session could not be registered to the first or merged with it; the message names it."""


@dataclass(frozen=True)
class SessionsConfig:
    """Registration and merging of scan sessions; each session is reconstructed with `reconstruct`."""

    reconstruct: ReconstructConfig = ReconstructConfig(silhouette_jump_truncations=2.0, noise_trunc_sigmas=3.0)
    """Settings for every session's own reconstruction. Silhouette pixels are left out of the fusion: each
    erodes the surface by about 0.05 mm, which the intersection keeps wherever either session did (a 5 mm
    bar, intersected at the exact pose: -3.4 % with them, -1.8 % without). For the same reason the
    truncation band stays three noise sigmas wide, not one session's 1.75: a narrower band erodes each
    session a little and the intersection keeps it, while the concave corners a wide band fills are carved by
    the other session (the six workshop tools at three noise levels: 16/18 within volume and COM at three
    sigmas, 11/18 at two, every volume 0.8-4.9 % lower). The table is cut 1.5 voxels up, as for one session:
    a higher cut gives more of a thin part over to the extrusion of a cross-section, and with the other
    session's cut band little of it is left seen (a wrench's 8.5 mm handle at high noise, 1.5 mm voxels:
    intersected at the exact pose, COM 2.70 mm cut at 3 voxels, 1.53 mm at 1.5)."""
    points: int = 3000
    """Observed points per session in the final refinement."""
    screen_points: int = 400
    """Observed points per session when screening the starts."""
    random_starts: int = 24
    """Extra starts (seeded random rotations) used when two principal moments of a solid are within
    `symmetric_moment_ratio` of each other, so its principal axes do not fix its orientation."""
    symmetric_moment_ratio: float = 0.1
    """Relative gap between principal moments below which the axes count as undetermined."""
    inlier_distance_m: float | None = None
    """Distance within which an observed point counts as consistent with the other solid [m].
    None: 3 voxels of the coarser session, or 4 depth-noise sigmas if larger."""
    min_fitness: float = 0.9
    """Fail unless at least this fraction of each session's observed points is consistent with the other."""
    normal_agreement: float = 0.5
    """Cosine between a point's normal and the other surface's normal above which the point is held on that
    surface (else only inside it): a turned-over tool's underside must not be pulled onto its top."""
    ambiguity: float = 0.1
    """Poses whose robust cost is within this fraction of the best are taken as equally supported by the
    observations (symmetric objects); each is refined and the smallest consistent intersection kept."""
    max_candidates: int = 6
    """At most this many such poses are refined and compared."""
    support_weight: float = 0.2
    """Weight of the resting contact, as a fraction of the observed points' total weight; 0 leaves it out.
    Each session's object rested on its support plane, so that plane, carried into the other session's world,
    touches the other session's observed surface where the object stood (the face of their convex hull that
    the downward ray from the centre of mass leaves through). A flat tool turned over shares only its rim
    with the first session, and the rim alone leaves its pitch 0.5 deg loose; its contacts pin it."""
    underside_normal_up: float = -0.5
    """Mesh vertices whose outward normal's component along their session's up is below this are not taken
    as observed. They face the table: the undersides of parts raised a few millimetres off it, seen only
    through that gap at grazing angles, where the table's truncation band meets theirs. On the caliper at
    the sensor level, such vertices held on the other session's surface lay 1.2 mm (mean) outside it at the
    exact pose; left out, its registration error went from 0.91 to 0.46 deg."""
    contact_smoothing_sigmas: float = 1.0
    """The resting contacts are found on the observed vertices each moved along its normal to the mean of its
    neighbours within this many depth-noise sigmas. The hull of the vertices as they are picks the noise's
    highest bumps: at the exact pose the six contact corners lay 0.66 mm (mean) beyond the other session's
    plane on the wrench at high noise (0.18 mm smoothed), 0.43 mm on the Allen key (0.02 mm smoothed)."""
    seed: int = 0
    """Seed of the point subsampling and the random starts."""


@dataclass(frozen=True, eq=False)
class Registration:
    """A later session's pose in the first session's world.

    T_first_from_session: 4x4 rigid transform [m] from this session's world to the first's.
    fitness: smaller of the two directions' consistent fractions, 0-1.
    rmse_m: RMS signed distance [m] over points where both sessions observed the surface.
    overlap: fraction of observed points on surface both sessions observed, 0-1.
    inlier_distance_m: the consistency distance used [m].
    start: which start won ("axes k" or "random k"); starts: how many were tried.
    consistent_poses: distinct poses within `ambiguity` of the best cost and above `min_fitness`; of several
      (a symmetric object), the one whose intersection with the first solid is smallest was kept.
    """

    T_first_from_session: np.ndarray
    fitness: float
    rmse_m: float
    overlap: float
    inlier_distance_m: float
    start: str
    starts: int
    consistent_poses: int

    def to_json(self) -> dict:
        return {
            "T_first_from_session": np.round(self.T_first_from_session, 9).tolist(),
            "fitness": self.fitness,
            "rmse_m": self.rmse_m,
            "overlap": self.overlap,
            "inlier_distance_m": self.inlier_distance_m,
            "start": self.start,
            "starts": self.starts,
            "consistent_poses": self.consistent_poses,
        }


def merge_sessions(scans: Sequence["Scan"], config: SessionsConfig = SessionsConfig()) -> Reconstruction:
    """Reconstruct each session, register the later ones to the first, and intersect their solids.

    Args:
        scans: the sessions, first one first (it defines the world and the placement).
        config: see `SessionsConfig`.

    Returns:
        A `Reconstruction` in the first session's world: the intersection mesh, the first session's support
        plane, the observed points of all sessions (in that world), and stats with each session's own
        reconstruction stats and registration under "sessions".

    Raises:
        SessionError: naming the session that could not be registered or merged.
        ReconstructError: from a session's own reconstruction.
    """
    if not scans:
        raise ValueError("merge_sessions needs at least one scan")
    recs = [reconstruct(scan, config.reconstruct) for scan in scans]
    return merge_reconstructions(recs, [scan.root for scan in scans], config)


def merge_reconstructions(
    recs: Sequence[Reconstruction], wheres: Sequence[object], config: SessionsConfig = SessionsConfig()
) -> Reconstruction:
    """`merge_sessions` on sessions already reconstructed; `wheres` name them (scan roots) in errors and stats."""
    import time

    t0 = time.perf_counter()
    first = recs[0]
    if len(recs) == 1:
        return first
    sessions = [{"root": str(wheres[0]), "volume_m3": float(first.mesh.volume), "stats": first.stats}]
    solids = [first.mesh]
    observed = [first.observed_points]
    for where, rec in zip(wheres[1:], recs[1:]):
        registration = register_session(first, rec, config, where)
        T = registration.T_first_from_session
        solids.append(rec.mesh.copy().apply_transform(T))
        observed.append(rec.observed_points @ T[:3, :3].T + T[:3, 3])
        sessions.append({"root": str(where), "volume_m3": float(rec.mesh.volume), "stats": rec.stats,
                         "registration": registration.to_json()})
    t1 = time.perf_counter()
    mesh = _intersect(solids, wheres)
    mesh = simplify_watertight(mesh, config.reconstruct.target_faces, wheres[0])
    stats = {
        **{k: v for k, v in first.stats.items() if k in ("voxel_size_m", "segmentation", "depth_noise_m")},
        "frame_count": sum(r.stats["frame_count"] for r in recs),
        "tsdf_s_per_frame": float(np.mean([r.stats["tsdf_s_per_frame"] for r in recs])),
        "sessions": sessions,
        "register_s": t1 - t0,
        "intersect_s": time.perf_counter() - t1,
        "faces": int(len(mesh.faces)),
        "volume_m3": float(mesh.volume),
    }
    return Reconstruction(
        mesh=mesh,
        support_plane=first.support_plane,
        object_points_count=sum(r.object_points_count for r in recs),
        voxel_size_m=max(r.voxel_size_m for r in recs),
        observed_points=np.concatenate(observed),
        stats=stats,
    )


def register_session(
    first: Reconstruction, later: Reconstruction, config: SessionsConfig = SessionsConfig(), where: object = "session"
) -> Registration:
    """The pose of `later`'s world in `first`'s, from their observed surfaces and solids (see the module doc).

    Raises:
        SessionError: naming `where` if the fitness is below `config.min_fitness`.
    """
    rng = np.random.default_rng(config.seed)
    tau = config.inlier_distance_m or max(
        3.0 * max(first.voxel_size_m, later.voxel_size_m),
        4.0 * max(first.stats.get("depth_noise_m", 0.0), later.stats.get("depth_noise_m", 0.0)),
    )
    a, b = (_Side.of(rec, config) for rec in (first, later))
    if len(a.points) < 50 or len(b.points) < 50:
        raise SessionError(f"{where}: too little observed surface to register ({len(b.points)} points, the first "
                           f"session {len(a.points)})")
    starts = _starts(first.mesh, later.mesh, config, rng)
    pivot = first.mesh.center_mass
    # the robust loss's scale: a voxel, so the few points where a solid's surface is eroded (thin parts) or
    # mislabelled as observed weigh little; `tau` only judges consistency
    scale = max(first.voxel_size_m, later.voxel_size_m)

    def subsample(count: int) -> tuple[np.ndarray, np.ndarray]:
        return (np.sort(rng.choice(len(a.points), min(count, len(a.points)), replace=False)),
                np.sort(rng.choice(len(b.points), min(count, len(b.points)), replace=False)))

    screen = subsample(config.screen_points)
    screened = sorted(
        ((*_refine(a, b, R0, t0, *screen, pivot, scale, config.normal_agreement,
                    config.support_weight, 30), label)
         for label, R0, t0 in starts),
        key=lambda s: s[2],
    )
    # poses the observations hardly tell apart (a symmetric object turned over looks the same either way)
    candidates = []
    for R, t, cost, label in screened:
        if cost > (1 + config.ambiguity) * screened[0][2] or len(candidates) == config.max_candidates:
            break
        if all(_angle_deg(R, other[0]) > 5.0 for other in candidates):
            candidates.append((R, t, label))
    final = subsample(config.points)
    refined = [(*_refine(a, b, R, t, *final, pivot, scale, config.normal_agreement,
                       config.support_weight, 60), label)
               for R, t, label in candidates]
    best_cost = min(r[2] for r in refined)
    checked = [(_check(a, b, R, t, tau, config.normal_agreement), cost, label) for R, t, cost, label in refined]
    consistent = [(c, label) for c, cost, label in checked
                  if cost <= (1 + config.ambiguity) * best_cost and c[0] >= config.min_fitness]
    if not consistent:
        fitness = max(c[0][0] for c in checked)
        raise SessionError(
            f"{where}: cannot register this scan session to the first: only {100 * fitness:.0f} % of the observed "
            f"surface lies on or inside the other session's solid (within {1000 * tau:.1f} mm; at least "
            f"{100 * config.min_fitness:.0f} % needed, best of {len(starts)} starts). Is it the same object, "
            "fully in view and segmented?"
        )
    # every consistent pose keeps the object inside both solids, so the smallest intersection is the
    # tightest bound: it carves what either session saw empty, wherever the symmetry put it
    if len(consistent) > 1:
        volumes = [_intersection_volume(first.mesh, later.mesh, c[3]) for c, _ in consistent]
        (fitness, rmse, overlap, T), label = consistent[int(np.argmin(volumes))]
    else:
        (fitness, rmse, overlap, T), label = consistent[0]
    registration = Registration(T, fitness, rmse, overlap, float(tau), label, len(starts), len(consistent))
    return registration


@dataclass(frozen=True, eq=False)
class _Side:
    """One session's solid (for signed distances) and observed surface (points with normals)."""

    scene: object  # open3d.t.geometry.RaycastingScene of the solid
    face_normals: np.ndarray  # [faces, 3]
    face_observed: np.ndarray  # [faces] bool
    points: np.ndarray  # observed vertices [m], [n, 3]
    normals: np.ndarray  # their outward normals, [n, 3]
    hull: np.ndarray  # the smoothed observed vertices' convex hull: per face (outward normal [3], offset [m]), [f, 4]
    hull_corners: np.ndarray  # its faces' corner points [m], [f, 3, 3]
    plane: tuple[np.ndarray, float]  # the support plane (up normal, offset [m])
    centre: np.ndarray  # the solid's centre of mass [m]
    extruded_m: float  # below this height over the support plane [m] the solid is the cut's extrusion, not seen

    @staticmethod
    def of(rec: Reconstruction, config: SessionsConfig) -> "_Side":
        import open3d as o3d
        from scipy.spatial import ConvexHull, cKDTree

        mesh = rec.mesh
        seen = np.asarray(rec.observed_points, float)
        tree = cKDTree(seen)
        spacing = float(np.median(tree.query(seen, k=2)[0][:, 1])) if len(seen) > 1 else rec.voxel_size_m
        # how far a mesh vertex may lie from the nearest observed point and still be seen: the points' own
        # spacing, and half a voxel for the mesh. Farther out is where closing added surface: on a caliper,
        # vertices 2-5 mm from the observed points sat 1-2 mm outside the truth, and held on the other
        # solid as if seen, they tilted the registration by 0.5 deg.
        radius = spacing + 0.5 * rec.voxel_size_m
        distance, _ = tree.query(mesh.vertices)
        normal, offset = rec.support_plane
        height = mesh.vertices @ normal + offset
        extruded = rec.stats.get("cut_height_m", 0.0) + rec.voxel_size_m
        vertex_normals = np.asarray(mesh.vertex_normals)
        near = (distance <= radius) & (height > extruded) & (vertex_normals @ normal >= config.underside_normal_up)
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(o3d.core.Tensor(np.asarray(mesh.vertices, np.float32)),
                            o3d.core.Tensor(np.asarray(mesh.faces, np.uint32)))
        points = np.asarray(mesh.vertices)[near]
        normals = vertex_normals[near]
        smoothed = _smoothed_along_normals(points, normals, config.contact_smoothing_sigmas
                                           * rec.stats.get("depth_noise_m", 0.0))
        hull = ConvexHull(smoothed) if len(points) >= 4 else None
        return _Side(scene, np.asarray(mesh.face_normals), near[mesh.faces].all(axis=1), points, normals,
                     hull.equations if hull is not None else np.empty((0, 4)),
                     smoothed[hull.simplices] if hull is not None else np.empty((0, 3, 3)),
                     (np.asarray(normal, float), float(offset)), np.asarray(mesh.center_mass), float(extruded))

    def contact(self, down: np.ndarray) -> np.ndarray:
        """The corners [m] of the hull face this side's object would rest on if `down` (unit, this side's world)
        pointed down: the face the ray from the centre of mass along `down` leaves through."""
        if not len(self.hull):
            return np.empty((0, 3))
        rate = self.hull[:, :3] @ down
        reach = np.where(rate > 1e-9, -(self.hull[:, :3] @ self.centre + self.hull[:, 3]) / np.maximum(rate, 1e-9),
                         np.inf)
        return self.hull_corners[int(np.argmin(reach))]

    def distances_to(
        self, other: "_Side", R: np.ndarray, t: np.ndarray, index: np.ndarray, agreement: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Residuals [m] of this side's observed points `index`, moved by (R, t), against `other`'s solid.

        Returns the residuals (signed distance where the nearest surface was observed by `other` and faces the
        same way, else its positive part, and 0 within `other`'s cut band), which points took the signed
        distance, and each residual's gradient with respect to the moved point (the nearest face's normal; zero
        where the residual is clipped).
        """
        import open3d as o3d

        q = (self.points[index] @ R.T + t).astype(np.float32)
        query = o3d.core.Tensor(q)
        closest = other.scene.compute_closest_points(query)
        nearest = closest["points"].numpy()
        face = closest["primitive_ids"].numpy().astype(np.int64)
        inside = other.scene.compute_occupancy(query).numpy() > 0.5
        distance = np.linalg.norm(q - nearest, axis=1).astype(np.float64)
        signed = np.where(inside, -distance, distance)
        facing = np.einsum("ij,ij->i", self.normals[index] @ R.T, other.face_normals[face]) > agreement
        on_surface = other.face_observed[face] & facing
        # within the other's cut band its solid is the extrusion of a cross-section, not a bound: a point poking
        # out there would pull the solids into each other (a caliper at the sensor level: 94 of 629 points
        # there, by up to 18 mm)
        outside = np.where(q @ other.plane[0] + other.plane[1] > other.extruded_m, np.maximum(signed, 0.0), 0.0)
        residual = np.where(on_surface, signed, outside)
        gradient = other.face_normals[face] * (on_surface | (outside > 0))[:, None]
        return residual, on_surface, gradient


def _check(a: _Side, b: _Side, R: np.ndarray, t: np.ndarray, tau: float, agreement: float):
    """(fitness, RMSE [m], overlap, T) of a pose on every observed point (see `Registration`)."""
    r_b, two_b, _ = b.distances_to(a, R, t, np.arange(len(b.points)), agreement)
    r_a, two_a, _ = a.distances_to(b, R.T, -R.T @ t, np.arange(len(a.points)), agreement)
    fitness = min(float(np.mean(r_a <= tau)), float(np.mean(r_b <= tau)))
    both = np.concatenate([r_a[two_a], r_b[two_b]])
    both = both[np.abs(both) <= tau]
    rmse = float(np.sqrt(np.mean(both**2))) if len(both) else float("nan")
    overlap = float(np.mean(np.concatenate([two_a, two_b])))
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return fitness, rmse, overlap, T


def _smoothed_along_normals(points: np.ndarray, normals: np.ndarray, radius_m: float) -> np.ndarray:
    """Each point [m] moved along its unit normal to the mean of the points within `radius_m` of it (itself
    included); along the normal only, so the surface is smoothed but its outline does not shrink."""
    from scipy.spatial import cKDTree

    if radius_m <= 0 or len(points) < 2:
        return points
    i, j = cKDTree(points).query_pairs(radius_m, output_type="ndarray").T
    sums, counts = points.copy(), np.ones(len(points))
    np.add.at(sums, i, points[j])
    np.add.at(sums, j, points[i])
    np.add.at(counts, i, 1.0)
    np.add.at(counts, j, 1.0)
    shift = np.einsum("ij,ij->i", sums / counts[:, None] - points, normals)
    return points + shift[:, None] * normals


def _angle_deg(R1: np.ndarray, R2: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(R1 @ R2.T) - 1.0) / 2.0, -1.0, 1.0))))


def _intersection_volume(first: "trimesh.Trimesh", later: "trimesh.Trimesh", T: np.ndarray) -> float:
    import trimesh

    return float(trimesh.boolean.intersection([first, later.copy().apply_transform(T)], engine="manifold").volume)


def _refine(
    a: _Side, b: _Side, R: np.ndarray, t: np.ndarray, ia: np.ndarray, ib: np.ndarray, pivot: np.ndarray,
    tau: float, agreement: float, support_weight: float, iterations: int,
) -> tuple[np.ndarray, np.ndarray, float]:
    """Levenberg-Marquardt on the robust (soft-L1, scale `tau` [m]) cost of both directions' residuals, plus
    the resting contacts' heights over the other session's support plane (quadratic, `support_weight`).

    (R, t) maps `b`'s world to `a`'s; updates rotate about `pivot` [m] (in `a`'s world). Returns the refined
    (R, t) and the mean cost [m^2].
    """
    from scipy.spatial.transform import Rotation

    na, oa = a.plane
    nb, ob = b.plane
    contact_weight = support_weight * (len(ia) + len(ib)) / 6.0  # 3 corners a side

    def evaluate(R, t):
        r_b, _, g_b = b.distances_to(a, R, t, ib, agreement)
        q_b = b.points[ib] @ R.T + t
        r_a, _, g_a = a.distances_to(b, R.T, -R.T @ t, ia, agreement)
        g_a = g_a @ R.T  # into a's world, where the pose change acts
        # where b stood, on b's plane, are a's observed points that touch b's plane carried into a's world
        up_b = R @ nb
        c_a = a.contact(-up_b)
        c_b = b.contact(-R.T @ na) @ R.T + t
        # a's points move by the inverse of the change: their residuals change with the opposite sign
        J = np.vstack([np.hstack([np.cross(q_b - pivot, g_b), g_b]),
                       -np.hstack([np.cross(a.points[ia] - pivot, g_a), g_a]),
                       np.hstack([np.cross(c_b - pivot, na), np.broadcast_to(na, c_b.shape)]),
                       -np.hstack([np.cross(c_a - pivot, up_b), np.broadcast_to(up_b, c_a.shape)])])
        r = np.concatenate([r_b, r_a])
        z = (r / tau) ** 2
        contact = np.concatenate([c_b @ na + oa, (c_a - t) @ up_b + ob])
        cost = float((np.sum(2.0 * tau**2 * (np.sqrt(1.0 + z) - 1.0)) + contact_weight * np.sum(contact**2))
                     / len(r))
        w = np.concatenate([1.0 / np.sqrt(1.0 + z), np.full(len(contact), contact_weight)])
        return np.concatenate([r, contact]), J, w, cost

    r, J, w, cost = evaluate(R, t)
    damping = 1e-3
    for _ in range(iterations):
        H = J.T @ (w[:, None] * J)
        g = J.T @ (w * r)
        step = np.linalg.solve(H + damping * np.diag(np.diag(H) + 1e-12), -g)
        dR = Rotation.from_rotvec(step[:3]).as_matrix()
        R_new, t_new = dR @ R, dR @ (t - pivot) + pivot + step[3:]
        trial = evaluate(R_new, t_new)
        if trial[3] < cost:
            R, t, (r, J, w, cost) = R_new, t_new, trial
            damping = max(damping / 3.0, 1e-7)
            if np.linalg.norm(step[:3]) < 1e-6 and np.linalg.norm(step[3:]) < 1e-7:
                break
        else:
            damping *= 4.0
            if damping > 1e4:
                break
    return R, t, cost


def _starts(first: "trimesh.Trimesh", later: "trimesh.Trimesh", config: SessionsConfig, rng: np.random.Generator):
    """(label, R0, t0) starts mapping the later solid onto the first: principal axes matched in the 4 proper
    ways, and random rotations if the axes are undetermined; centres of mass matched."""
    from scipy.spatial.transform import Rotation

    Va, Vb = first.principal_inertia_vectors, later.principal_inertia_vectors  # rows are the axes
    rotations = []
    for signs in np.array(np.meshgrid([1, -1], [1, -1], [1, -1])).T.reshape(-1, 3):
        R = Va.T @ np.diag(signs) @ Vb
        if np.linalg.det(R) > 0:
            rotations.append((f"axes {len(rotations)}", R))
    gaps = [np.min(np.diff(np.sort(m)) / np.max(m)) for m in (first.principal_inertia_components,
                                                              later.principal_inertia_components)]
    if min(gaps) < config.symmetric_moment_ratio:
        seed = int(rng.integers(2**31))
        for k, R in enumerate(Rotation.random(config.random_starts, random_state=seed).as_matrix()):
            rotations.append((f"random {k}", R))
    ca, cb = first.center_mass, later.center_mass
    return [(label, R, ca - R @ cb) for label, R in rotations]


def _intersect(solids: list, wheres: Sequence[object]):
    """The solids' intersection (manifold3d), its largest closed piece with outward normals."""
    import trimesh

    try:
        mesh = trimesh.boolean.intersection(solids, engine="manifold")
    except Exception as exc:  # manifold3d raises its own types for degenerate input
        raise SessionError(f"{wheres[1]}: intersecting the sessions' solids failed ({exc})") from exc
    pieces = [p for p in mesh.split(only_watertight=True) if p.volume > 0] if len(mesh.faces) else []
    if not pieces:
        raise SessionError(f"{wheres[1]}: the sessions' solids do not overlap after registration")
    best = max(pieces, key=lambda p: p.volume)
    trimesh.repair.fix_normals(best)
    return best
