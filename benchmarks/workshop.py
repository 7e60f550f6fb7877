"""`twin bench workshop`: the Workshop Tools benchmark (Nadeau, Giamou & Kelly, "The Sum of Its Parts", ICRA 2023)
at the authors' noise levels, scored with the authors' metrics beside their published OLS, GEO and HPS results.

Data: ../shared/data/workshop-tools (six of the twenty tools, their simulated stop-and-go wrist recordings,
100 Hz, 10 s, SolidWorks truth, the authors' part segmentations, and `derived/results_pkl_flat.csv`, the flat
copy of their `Experiments/results.pkl`). Source of the noise levels and metrics:
utiasSTARS/inertial-identification-with-part-segmentation@4892808,
`inertial-parameters-identification/RunExperiments.py` (levels) and `InertialParametersEstimation.py`
(`MassErrorMetric`, `CentreOfMassErrorMetric`, `InertiaErrorMetric`, `GeodesicErrorMetric`, `DataLoader`'s
`extents_S`), ported in `workshop_errors`.

Noise: the authors add zero-mean Gaussian noise to force, torque, linear and angular acceleration of each
record. Force and torque noise is added here to the wrench as they do. We read poses, not accelerations, so the
kinematics' noise is carried into the poses as white noise whose raw second difference at the 100 Hz sample
rate has the authors' acceleration standard deviation: position sigma_a dt^2 / sqrt(6) per axis, rotation
sigma_alpha dt^2 / sqrt(6) per axis (1e-6 m and 1e-5 rad at "Low").
"""

from __future__ import annotations

import csv
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

WORKSHOP = Path(__file__).resolve().parents[2] / "shared" / "data" / "workshop-tools"
WORKSHOP_TOOLS = ("Hammer", "Rubber Mallet", "Screwdriver", "Electronic Caliper", "Allen Key", "Adjustable Wrench")
MIRROR = np.diag([1.0, 1.0, -1.0])
"""The workshop-tools simulations obey F = m (a + g) with g pointing down, which is Newton's law with
gravity pointing up. Mirroring world and body through z (pseudo-vectors: torque, angular velocity
change sign too) turns them into recordings of our world, where gravity points down."""

NOISE_LEVELS = {
    # level: (force [N], torque [N m], linear acceleration [m/s^2], angular acceleration [rad/s^2])
    "No": (0.0, 0.0, 0.0, 0.0),
    "Low": (0.05, 0.0025, 0.025, 0.25),
    "Mod": (0.1, 0.005, 0.05, 0.5),
    "High": (0.2, 0.01, 0.1, 1.0),
}
"""The authors' noise levels (RunExperiments.py: `wrench_noise_std_dev`, `acc_noise_std_dev`; velocity noise 0)."""

TOOL_MATERIAL = {"Hammer": "steel", "Rubber Mallet": "rubber", "Screwdriver": "pvc_rigid",
                 "Electronic Caliper": "stainless_steel", "Allen Key": "steel", "Adjustable Wrench": "steel"}
"""What a user would name each tool's material (its most visible part), from the library."""

PUBLISHED = ("OLS", "GEO", "HPS")

WEIGHED_STD_KG = 1e-4
"""The "kept, mass weighed" row: the tool weighed on a lab balance (0.1 g standard deviation) and passed as a
build's --mass. The authors' GEO is given the true mass in its prior, a scale's worth of information the
recordings alone cannot match (their mass bound is printed beside them)."""


def pose_noise_from_acceleration(accel_m_s2: float, angular_rad_s2: float, dt_s: float = 0.01) -> tuple[float, float]:
    """White pose noise (position [m], rotation [rad] per axis) whose raw second difference at `dt_s` has the
    given acceleration standard deviations: a second difference of white noise has variance 6 sigma^2 / dt^4."""
    return accel_m_s2 * dt_s**2 / np.sqrt(6.0), angular_rad_s2 * dt_s**2 / np.sqrt(6.0)


def workshop_recording(tool: str, directory: Path, rng: np.random.Generator, root: Path = WORKSHOP,
                       level: str = "Low", pose_sigma: tuple[float, float] | None = (2e-5, 2e-4)):
    """One tool's simulated recording, mirrored (see MIRROR) and written as MCAP with the force and torque noise
    of `level` (`NOISE_LEVELS`) and white pose noise `pose_sigma` (position [m], rotation [rad]; None: the level's
    acceleration noise carried into the poses, `pose_noise_from_acceleration`); returns (recording,
    uniform-density prior at the true mass, X_tracked_body, true COM shift in the mirrored object frame [m])."""
    case = workshop_case(tool, directory, rng, root, level, pose_sigma)
    return case.recording, case.uniform, case.X_tracked_body, np.asarray(case.truth.com) - np.asarray(case.uniform.com)


@dataclass(frozen=True)
class WorkshopCase:
    """One tool's recording and everything to score it.

    All bodies in the mirrored object frame (see MIRROR) [kg, m, kg m^2 about the COM]: truth (SolidWorks),
    uniform (the mesh at uniform density and the true mass, as the authors' GEO prior). mesh: trimesh in that
    frame [m]; parts: the authors' segmentation as `BodyMoments` per part (their HPS input); points, volumes:
    the segmentation's points (tetrahedron centroids) in that frame [m] and their volumes scaled to the
    mesh's [m^3]; grasp: the grasp
    (sensor) frame in the dataset's mesh frame, 4x4; extents_mesh: bounding-box extents of the segmentation's
    points in the mesh frame [m] (the authors' bounding box).
    """

    tool: str
    recording: object
    truth: object
    uniform: object
    X_tracked_body: object
    mesh: object
    parts: tuple
    points: np.ndarray
    volumes: np.ndarray
    grasp: np.ndarray
    extents_mesh: np.ndarray


def _mirror4() -> np.ndarray:
    return np.block([[MIRROR, np.zeros((3, 1))], [np.zeros((1, 3)), np.ones((1, 1))]])


def workshop_case(tool: str, directory: Path, rng: np.random.Generator, root: Path = WORKSHOP, level: str = "Low",
                  pose_sigma: tuple[float, float] | None = None) -> WorkshopCase:
    """`workshop_recording`'s recording with the truth, mesh and part segmentation to score and prime it."""
    import trimesh
    import yaml
    from scipy.spatial.transform import Rotation

    from assets import Inertial, Pose
    from assets.recording import PoseTrack, WrenchTrack
    from pipelines.logs import read_recording
    from pipelines.synth.recording import write_recording

    if level not in NOISE_LEVELS:
        raise ValueError(f"workshop noise level {level!r}: expected one of {list(NOISE_LEVELS)}")
    folder = root / "data" / "Workshop Tools Dataset" / tool
    npz = root / "derived" / "simulations_npz" / f"{tool.replace(' ', '_')}.npz"
    if not npz.is_file() or not folder.is_dir():
        raise FileNotFoundError(f"{npz}: workshop-tools data not found")
    truth_yaml = yaml.safe_load((folder / "Inertia.yaml").read_text())["OBJECT"]
    d = np.load(npz)
    mesh = trimesh.load(folder / "mesh.ply", force="mesh")
    mesh.apply_scale(1e-3)
    mesh.apply_transform(_mirror4())
    mass = float(truth_yaml["MASS"])
    mesh.density = mass / mesh.volume
    uniform = Inertial(mass, tuple(np.asarray(mesh.center_mass)), np.asarray(mesh.moment_inertia))
    true_com = MIRROR @ np.asarray(truth_yaml["COM_WRT_MESH"], dtype=float)
    true_inertia = MIRROR @ np.asarray(truth_yaml["INERTIA_WRT_COM"], dtype=float) @ MIRROR
    truth = Inertial(mass, tuple(true_com), true_inertia)
    grasp = np.asarray(truth_yaml["GRASP_WRT_MESH"], dtype=float)
    X_tracked_body = np.linalg.inv(grasp)
    X_tracked_body[:3, :3] = MIRROR @ X_tracked_body[:3, :3] @ MIRROR
    X_tracked_body[:3, 3] = MIRROR @ X_tracked_body[:3, 3]
    parts, points, volumes, extents = _segmentation_parts(root, tool, mesh.volume)

    force_n, torque_nm, accel, angular = NOISE_LEVELS[level]
    sigma_p, sigma_r = pose_noise_from_acceleration(accel, angular) if pose_sigma is None else pose_sigma
    t = d["timestamp"]
    T = d["ft_pose"]
    R = MIRROR @ T[:, :3, :3] @ MIRROR
    position = (T[:, :3, 3] @ MIRROR) + rng.normal(0, 1, (len(t), 3)) * sigma_p
    quat = (Rotation.from_matrix(R) * Rotation.from_rotvec(rng.normal(0, 1, (len(t), 3)) * sigma_r)).as_quat()
    force = d["ft_value"][:, :3] @ MIRROR + rng.normal(0, 1, (len(t), 3)) * force_n
    torque = -(d["ft_value"][:, 3:] @ MIRROR) + rng.normal(0, 1, (len(t), 3)) * torque_nm
    path = directory / f"{tool.replace(' ', '_')}.mcap"
    write_recording(path, pose=PoseTrack(t, position, quat, "world", "ft_sensor", "/tracker/pose"),
                    wrench=WrenchTrack(t, force, torque, "/ft_sensor/wrench", "world"))
    pose = Pose(tuple(X_tracked_body[:3, 3]), tuple(Rotation.from_matrix(X_tracked_body[:3, :3]).as_quat()))
    return WorkshopCase(tool, read_recording(path), truth, uniform, pose, mesh, parts, points, volumes, grasp, extents)


def _segmentation_parts(root: Path, tool: str, volume_m3: float):
    """The authors' part segmentation (data/Segmentations, their HPS input) as per-part `BodyMoments` in the
    mirrored object frame: each point the centroid of a tetrahedron of the given volume, the volumes scaled to
    the mesh's; the points and volumes themselves; and the points' bounding-box extents in the dataset's mesh
    frame [m]."""
    name = tool.replace(" ", "_")
    points, labels, volumes = _read_segmentation(root / "data" / "Segmentations" / name / f"{name}.ply")
    extents = points.max(axis=0) - points.min(axis=0)
    volumes = volumes * volume_m3 / volumes.sum()
    mirrored = points @ MIRROR
    return _cloud_parts(mirrored, volumes, labels), mirrored, volumes, extents


def _cloud_parts(points: np.ndarray, volumes: np.ndarray, labels: np.ndarray) -> tuple:
    """`BodyMoments` per label of volume-weighted points [m, m^3]."""
    from pipelines.priors import BodyMoments

    parts = []
    for label in np.unique(labels):
        keep = labels == label
        v, p = volumes[keep], points[keep]
        parts.append(BodyMoments(float(v.sum()), (v[:, None] * p).sum(axis=0), np.einsum("n,ni,nj->ij", v, p, p)))
    return tuple(parts)


def geometry_parts(case: WorkshopCase, count: int = 4, seed: int = 0) -> tuple:
    """Parts from geometry alone: the segmentation's points split into `count` clusters by position (k-means,
    the labels unused), as a build's decomposition splits a mesh without knowing its materials."""
    from scipy.cluster.vq import kmeans2

    _, labels = kmeans2(case.points, count, seed=seed, minit="++")
    return _cloud_parts(case.points, case.volumes, labels)


def _read_segmentation(path: Path):
    """Points [m], segment ids and tetrahedron volumes of an ASCII PLY of the authors' segmentation."""
    lines = path.read_text().splitlines()
    names, count, start = [], 0, 0
    for k, line in enumerate(lines):
        words = line.split()
        if words[:2] == ["element", "vertex"]:
            count = int(words[2])
        elif words[:1] == ["property"]:
            names.append(words[-1])
        elif words[:1] == ["end_header"]:
            start = k + 1
            break
    table = np.array([[float(x) for x in line.split()] for line in lines[start:start + count]])
    col = {n: i for i, n in enumerate(names)}
    return table[:, [col["x"], col["y"], col["z"]]], table[:, col["segmentation"]].astype(int), table[:, col["volume"]]


# ---------------------------------------------------------------------------------------------------------------
# the authors' metrics (InertialParametersEstimation.py), on bodies in the sensor frame


def sensor_frame_parameters(body, grasp: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """(mass [kg], COM [m], inertia about the sensor origin [kg m^2]) in the dataset's sensor frame, from a body in
    the mirrored object frame; as the authors' `DataLoader.inertia_wrt_sensor` (the sensor frame is the grasp
    frame there, X_ST = I)."""
    X_SM = np.linalg.inv(grasp)
    R = X_SM[:3, :3]
    m = float(body.mass)
    c = R @ (MIRROR @ np.asarray(body.com, dtype=float)) + X_SM[:3, 3]
    I_c = R @ MIRROR @ np.asarray(body.inertia_matrix(), dtype=float) @ MIRROR @ R.T
    S = _skew(c)
    return m, c, I_c - m * S @ S


def _skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def pseudo_inertia(mass: float, com: np.ndarray, inertia: np.ndarray) -> np.ndarray:
    """The 4x4 pseudo-inertia [[tr(J)/2 1 - J, m c], [m c^T, m]] of `ProjectOntoManifold` (J about the origin)."""
    P = np.zeros((4, 4))
    P[:3, :3] = 0.5 * np.trace(inertia) * np.eye(3) - inertia
    P[:3, 3] = P[3, :3] = mass * np.asarray(com)
    P[3, 3] = mass
    return P


def geodesic_distance(estimate: np.ndarray, truth: np.ndarray) -> float:
    """Riemannian distance between two pseudo-inertias, sqrt(1/2 sum log^2 eig(P_est^-1 P_true)) (Lee, Wensing &
    Park 2019, eq. 17; the authors' `GeodesicErrorMetric`); -1 when the estimate is not positive definite."""
    if not _positive_definite(estimate) or not _positive_definite(truth):
        return -1.0
    eig = np.linalg.eigvals(np.linalg.solve(estimate, truth)).real
    return float(np.sqrt(0.5 * np.sum(np.log(eig) ** 2)))


def _positive_definite(P: np.ndarray) -> bool:
    if not np.allclose(P, P.T):
        return False
    try:
        np.linalg.cholesky(P)
        return True
    except np.linalg.LinAlgError:
        return False


def workshop_errors(estimate, truth, grasp: np.ndarray, extents_mesh: np.ndarray) -> dict:
    """The authors' errors of one estimate (bodies in the mirrored object frame, `Inertial`):

    mass_pct: 100 |m - m*| / m*; com_pct: per sensor axis 100 |c - c*| / |bbox|, averaged, each axis truncated
    to a whole percent as their int array does (com_exact_pct: not truncated); inertia_pct: per unique entry of
    J about the sensor origin 100 |J - J*| / ((m*/12)(delta_ij (a^2+b^2+c^2) - a_i a_j)), averaged; riemannian:
    `geodesic_distance` (-1: not physical); consistent: riemannian != -1.
    """
    m, c, J = sensor_frame_parameters(estimate, grasp)
    m0, c0, J0 = sensor_frame_parameters(truth, grasp)
    a = np.abs(np.linalg.inv(grasp)[:3, :3] @ extents_mesh)
    com_axes = 100 * np.abs(c - c0) / a
    denom = (m0 / 12) * (np.eye(3) * np.sum(a**2) - np.outer(a, a))
    inertia = 100 * np.abs((J - J0) / denom)
    unique = np.array([inertia[0, 0], inertia[0, 1], inertia[0, 2], inertia[1, 1], inertia[1, 2], inertia[2, 2]])
    riemannian = geodesic_distance(pseudo_inertia(m, c, J), pseudo_inertia(m0, c0, J0))
    return {"mass_pct": float(100 * abs(m - m0) / m0), "com_pct": float(np.mean(np.trunc(com_axes))),
            "com_exact_pct": float(np.mean(com_axes)), "inertia_pct": float(np.mean(unique)),
            "riemannian": riemannian, "consistent": riemannian != -1.0}


def published_results(root: Path = WORKSHOP, tools=WORKSHOP_TOOLS) -> dict:
    """{(algorithm, level): {metric: six-tool mean}} from `derived/results_pkl_flat.csv` (the authors' results.pkl),
    with "consistent" the share of runs with a geodesic distance and "riemannian" their mean over consistent runs
    (NaN as their AnalyzeExperiments when any is not)."""
    rows = list(csv.DictReader((root / "derived" / "results_pkl_flat.csv").open()))
    names = {t.replace(" ", "_") for t in tools}
    out = {}
    for algo in PUBLISHED:
        for level in NOISE_LEVELS:
            sel = [r for r in rows if r["tool"] in names and r["algorithm"] == algo and r["noise"] == level]
            geo = np.array([float(r["geodesic_riemannian"]) for r in sel])
            consistent = geo != -1
            out[algo, level] = {
                "mass_pct": float(np.mean([float(r["size_based_mass_err_pct"]) for r in sel])),
                "com_pct": float(np.mean([float(r["size_based_com_err_pct_of_bbox"]) for r in sel])),
                "inertia_pct": float(np.mean([float(r["size_based_inertia_err_pct"]) for r in sel])),
                "riemannian": float(geo.mean()) if consistent.all() else float("nan"),
                "riemannian_consistent": float(geo[consistent].mean()) if consistent.any() else float("nan"),
                "consistent": float(consistent.mean()),
            }
    return out


# ---------------------------------------------------------------------------------------------------------------
# the bench


def material_prior(mesh, material: str):
    """The geometry x material prior a build starts from: the mesh at the named material's central density
    (uniform), and bounds C from its density range and the mesh's box, as `uniform_density_prior` makes them
    (the dataset's CAD meshes are not all closed, so the volume is trimesh's signed sum)."""
    from assets import Inertial
    from assets.materials import material_range
    from pipelines.identify import InertialBounds

    entry = material_range(material)
    mesh = mesh.copy()
    mesh.density = 1.0
    volume = float(mesh.volume)
    unit = np.asarray(mesh.moment_inertia)
    com = np.asarray(mesh.center_mass)
    half = 0.5 * (mesh.bounds[1] - mesh.bounds[0])
    lower = (entry.density_low * volume, *(com - half), *(entry.density_low * np.diag(unit) * 0.3))
    upper = (entry.density_high * volume, *(com + half), *(entry.density_high * np.diag(unit) * 2.0))
    return Inertial(entry.density * volume, tuple(com), entry.density * unit), InertialBounds(lower, upper)


def mass_bound_pct(case: WorkshopCase, level: str, root: Path = WORKSHOP) -> float:
    """Expected mean |mass error| [%] of an efficient unbiased estimator that knows the motion exactly (the
    Cramer-Rao bound of the Newton-Euler regression under the level's force and torque noise, the other nine
    parameters unknown): sqrt(2/pi) sigma_m / m."""
    from scipy.spatial.transform import Rotation

    from assets.conventions import GRAVITY_M_S2
    from pipelines.identify.least_squares import newton_euler_regressor

    force_n, torque_nm, _, _ = NOISE_LEVELS[level]
    if force_n == 0:
        return 0.0
    d = np.load(root / "derived" / "simulations_npz" / f"{case.tool.replace(' ', '_')}.npz")
    R = MIRROR @ d["ft_pose"][:, :3, :3] @ MIRROR
    inv = Rotation.from_matrix(R).inv()
    acc = d["ft_acc"][:, :3] @ MIRROR  # mirrored: vectors M v, pseudo-vectors -M v
    omega, alpha = -(d["ft_vel"][:, 3:] @ MIRROR), -(d["ft_acc"][:, 3:] @ MIRROR)
    A = newton_euler_regressor(inv.apply(acc - GRAVITY_M_S2), inv.apply(omega), inv.apply(alpha))
    w = np.array([1 / force_n**2] * 3 + [1 / torque_nm**2] * 3)
    fisher = np.einsum("nik,i,nil->kl", A, w, A)
    sigma = float(np.sqrt(np.linalg.inv(fisher)[0, 0]))
    return float(100 * np.sqrt(2 / np.pi) * sigma / case.truth.mass)


def bench_workshop(seeds: int = 10, levels: tuple[str, ...] = ("No", "Low", "Mod", "High"),
                   tools: tuple[str, ...] = WORKSHOP_TOOLS, method: str = "ls", parts: str = "segmentation",
                   root: Path = WORKSHOP) -> list[dict]:
    """The six Workshop Tools at the authors' noise levels, `seeds` noise draws each, identified as a build
    does (`identify_held`) from the mesh and a named material (`TOOL_MATERIAL`, `material_prior`); prints the
    authors' metrics averaged over tools and seeds per level and estimator, beside their published OLS, GEO
    and HPS results for the same tools, and returns one row per tool, level, seed and estimator.

    Estimators: least squares (raw); the posterior with the uniform-density prior; the posterior with
    per-part densities over `parts`: "segmentation" (the authors' part segmentation, their HPS input),
    "geometry" (`geometry_parts`: four clusters of the same points by position, no labels) or "none"; what
    `identify_held` keeps with those parts; that with the tool weighed (`WEIGHED_STD_KG`), as `--mass` does in
    a build. method "ls" skips the Newton fit, "newton" runs it as a build
    does; with one recording and no held-out one the posterior is kept either way (held.py), so "newton"
    changes only the time (3-15 s a run here). A run that raises is counted, not fatal. Coverage: the share of the ten flat parameters (mass, COM, inertia about the COM) whose reported
    95 % interval holds the truth.
    """
    from assets import flat_inertial
    from pipelines.identify import IdentifyConfig, identify_held, with_weighed_mass
    from pipelines.identify.posterior import data_term_from_least_squares, identify_posterior

    if parts not in ("segmentation", "geometry", "none"):
        raise ValueError(f"bench workshop: parts {parts!r}, expected 'segmentation', 'geometry' or 'none'")
    if method not in ("newton", "ls"):
        raise ValueError(f"bench workshop: method {method!r}, expected 'newton' or 'ls'")
    unknown = [lv for lv in levels if lv not in NOISE_LEVELS]
    if unknown:
        raise ValueError(f"bench workshop: unknown noise level(s) {unknown}, expected some of {list(NOISE_LEVELS)}")
    rows, bounds_pct = [], {}
    for level in levels:
        for seed in range(seeds):
            rng = np.random.default_rng(1000 * list(NOISE_LEVELS).index(level) + seed)
            for tool in tools:
                with tempfile.TemporaryDirectory() as tmp:
                    case = workshop_case(tool, Path(tmp), rng, root, level)
                if seed == 0:
                    bounds_pct[level, tool] = mass_bound_pct(case, level, root)
                prior, bounds = material_prior(case.mesh, TOOL_MATERIAL[tool])
                split = {"segmentation": case.parts, "geometry": geometry_parts(case), "none": ()}[parts]
                part_P = np.array([p.pseudo_inertia() for p in split]).reshape(-1, 4, 4)
                found, t0 = {}, time.perf_counter()
                try:
                    held = identify_held([case.recording], None, case.X_tracked_body, prior, bounds, IdentifyConfig(),
                                         method, parts=part_P if len(part_P) else None)
                    seconds = time.perf_counter() - t0
                    uniform = identify_posterior(
                        [data_term_from_least_squares(held.least_squares.pi, held.least_squares.normal,
                                                      held.least_squares.meat)],
                        case.X_tracked_body, prior, (bounds.lower[0], bounds.upper[0]))
                    found = {"least squares": (held.least_squares.inertial, held.least_squares.covariance),
                             "posterior, uniform density": (uniform.inertial, uniform.covariance),
                             f"posterior, {parts} parts": (held.posterior.inertial, held.posterior.covariance),
                             "kept": (held.inertial, held.covariance)}
                    # a stream of its own per run, so the other rows' noise draws stay as they were
                    scale = np.random.default_rng([list(NOISE_LEVELS).index(level), seed, tools.index(tool)])
                    weighed = case.truth.mass + scale.normal(0.0, WEIGHED_STD_KG)
                    found["kept, mass weighed"] = with_weighed_mass(held.inertial, held.covariance, weighed,
                                                                    WEIGHED_STD_KG)
                    error, choice, dominated = None, held.choice, list(held.prior_dominated)
                except Exception as exc:  # noqa: BLE001 - the bench counts what raises
                    seconds, error, choice, dominated = time.perf_counter() - t0, f"{type(exc).__name__}: {exc}", "", []
                    print(f"  {tool} {level} seed {seed}: raised {error}", flush=True)
                truth = flat_inertial(case.truth)
                for estimator, (body, cov) in found.items():
                    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
                    rows.append({"tool": tool, "level": level, "seed": seed, "estimator": estimator,
                                 **workshop_errors(body, case.truth, case.grasp, case.extents_mesh),
                                 "covered": (np.abs(flat_inertial(body) - truth) <= 1.96 * std).tolist(),
                                 "seconds": seconds, "choice": choice if estimator == "kept" else "",
                                 "prior_dominated": dominated if estimator == "kept" else []})
                if error is not None:
                    rows.append({"tool": tool, "level": level, "seed": seed, "estimator": "kept", "error": error})
            print(f"  {level} seed {seed} done", flush=True)
    _print_workshop_table(rows, levels, tools, bounds_pct, root)
    return rows


def _print_workshop_table(rows: list[dict], levels, tools, bounds_pct: dict, root: Path) -> None:
    published = published_results(root, tools)
    estimators = list(dict.fromkeys(r["estimator"] for r in rows))
    header = (f"{'level':5} {'estimator':28} {'runs':>5} {'raised':>6} {'consistent %':>12} {'mass %':>7} "
              f"{'COM %':>6} {'(exact)':>7} {'inertia %':>9} {'Riemannian':>10} {'95% cover':>9} {'s/run':>6}")
    print(header)
    print("-" * len(header))
    for level in levels:
        for estimator in estimators:
            sel = [r for r in rows if r["level"] == level and r["estimator"] == estimator]
            ok = [r for r in sel if "error" not in r]
            if not sel:
                continue
            raised = len(sel) - len(ok)
            consistent = [r for r in ok if r["consistent"]]
            mean = lambda key, rs=ok: float(np.mean([r[key] for r in rs])) if rs else float("nan")  # noqa: E731
            riem = mean("riemannian", consistent)
            cover = float(np.mean([np.mean(r["covered"]) for r in ok])) if ok else float("nan")
            print(f"{level:5} {estimator:28} {len(sel):>5} {raised:>6} {100 * len(consistent) / max(len(ok), 1):>12.0f} "
                  f"{mean('mass_pct'):>7.3f} {mean('com_pct'):>6.2f} {mean('com_exact_pct'):>7.2f} "
                  f"{mean('inertia_pct'):>9.2f} {riem:>10.3f}{'*' if len(consistent) < len(ok) else ' '}"
                  f"{100 * cover:>8.0f}% {mean('seconds'):>6.2f}")
        for algo in PUBLISHED:
            p = published[algo, level]
            riem = p["riemannian"] if np.isfinite(p["riemannian"]) else p["riemannian_consistent"]
            star = "*" if not np.isfinite(p["riemannian"]) else " "
            print(f"{level:5} {'published ' + algo:28} {len(tools):>5} {'-':>6} {100 * p['consistent']:>12.0f} "
                  f"{p['mass_pct']:>7.3f} {p['com_pct']:>6.2f} {'-':>7} {p['inertia_pct']:>9.2f} {riem:>10.3f}{star}"
                  f"{'-':>9} {'-':>6}")
        bound = [bounds_pct[level, t] for t in tools if (level, t) in bounds_pct]
        if bound:
            print(f"{level:5} {'mass bound (exact motion)':28} {'':>5} {'':>6} {'':>12} {np.mean(bound):>7.3f}")
    print("COM %: the authors' metric, each axis truncated to a whole percent as their int array does; (exact): "
          "not truncated. Riemannian: mean over physically consistent runs (* some were not). mass bound: the "
          "expected mean |error| of an efficient estimator that knows the motion exactly (Cramer-Rao).")
    kept = [r for r in rows if r["estimator"] == "kept" and "error" not in r]
    dominated: dict = {}
    for r in kept:
        for name in r["prior_dominated"]:
            dominated[name] = dominated.get(name, 0) + 1
    if kept:
        print(f"prior-dominated parameters of the kept estimate (runs of {len(kept)}): "
              + (", ".join(f"{k} {v}" for k, v in sorted(dominated.items(), key=lambda kv: -kv[1])) or "none"))
        choices: dict = {}
        for r in kept:
            key = r["choice"].split(";")[0]
            choices[key] = choices.get(key, 0) + 1
        for text, count in choices.items():
            print(f"kept in {count} runs: {text}")
