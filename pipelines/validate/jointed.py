"""`validate_jointed_exports`: a jointed part's joint as each loader reads it."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from assets import Asset
from exporters.names import joint_name, mjcf_name, urdf_name, usd_prim_name

from .exports import paths_from, reference_size_m
from .loaders import MJ_STEPS, rotation_from_wxyz
from .report import DEFAULT_TOLERANCE, ValidationError


def _read_mujoco_jointed(asset: Asset, path: Path) -> dict:
    import mujoco

    model = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    name = mjcf_name(asset.name)
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
    joint = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, joint_name(name))
    if body < 0 or joint < 0:
        raise ValueError(f"no body {name!r} with joint {joint_name(name)!r}")
    R_iner = rotation_from_wxyz(model.body_iquat[body])
    R_body = data.xmat[body].reshape(3, 3).copy()
    dof = model.jnt_dofadr[joint]
    kinds = {int(mujoco.mjtJoint.mjJNT_SLIDE): "prismatic", int(mujoco.mjtJoint.mjJNT_HINGE): "revolute"}
    reading = {
        "mass": float(model.body_mass[body]), "com": np.array(model.body_ipos[body]),
        "inertia": R_iner @ np.diag(model.body_inertia[body]) @ R_iner.T,
        "type": kinds.get(int(model.jnt_type[joint]), "other"), "axis": R_body @ model.jnt_axis[joint],
        "point": data.xanchor[joint].copy(),
        "lower": float(model.jnt_range[joint, 0]), "upper": float(model.jnt_range[joint, 1]),
        "damping": float(model.dof_damping[dof]), "friction": float(model.dof_frictionloss[dof]),
    }
    for _ in range(MJ_STEPS):  # it must simulate
        mujoco.mj_step(model, data)
    if not np.all(np.isfinite(data.qpos)):
        raise ValueError(f"state not finite after {MJ_STEPS} steps")
    return reading


def _read_newton_jointed(asset: Asset, path: Path, fmt: str) -> dict:
    import newton
    from scipy.spatial.transform import Rotation

    builder = newton.ModelBuilder()
    {"mjcf": builder.add_mjcf, "urdf": builder.add_urdf, "usd": builder.add_usd}[fmt](str(path))
    model = builder.finalize(device="cpu")
    # labels are paths ("model/worldbody/body", "robot/link", "/prim"); the names cannot hold a "/"
    labels = [str(label).split("/")[-1] for label in builder.body_label]
    name = {"mjcf": mjcf_name, "urdf": urdf_name, "usd": usd_prim_name}[fmt](asset.name)
    if name not in labels:
        raise ValueError(f"no body {name!r} among {labels}")
    body = labels.index(name)
    joint = int(np.flatnonzero(model.joint_child.numpy() == body)[0])
    dof = int(model.joint_qd_start.numpy()[joint])
    X_p = model.joint_X_p.numpy()[joint].astype(float)
    parent = int(model.joint_parent.numpy()[joint])
    X_parent = model.body_q.numpy()[parent].astype(float) if parent >= 0 else np.array([0, 0, 0, 0, 0, 0, 1.0])
    R_parent, R_p = Rotation.from_quat(X_parent[3:]), Rotation.from_quat(X_p[3:])
    kinds = {int(newton.JointType.PRISMATIC): "prismatic", int(newton.JointType.REVOLUTE): "revolute"}
    com = model.body_com.numpy()[body].astype(float)
    if fmt == "urdf":
        from exporters.urdf import urdf_link_offset

        com = com - urdf_link_offset(asset)
    return {
        "mass": float(model.body_mass.numpy()[body]), "com": com,
        "inertia": model.body_inertia.numpy()[body].astype(float),
        "type": kinds.get(int(model.joint_type.numpy()[joint]), "other"),
        "axis": (R_parent * R_p).apply(model.joint_axis.numpy()[dof].astype(float)),
        "point": X_parent[:3] + R_parent.apply(X_p[:3]),
        "lower": float(model.joint_limit_lower.numpy()[dof]), "upper": float(model.joint_limit_upper.numpy()[dof]),
        "damping": float(builder.joint_damping[dof]), "friction": float(builder.joint_friction[dof]),
    }


def _read_yourdfpy_jointed(asset: Asset, path: Path) -> dict:
    import yourdfpy

    from exporters.urdf import urdf_link_offset

    urdf = yourdfpy.URDF.load(str(path), build_collision_scene_graph=True, load_collision_meshes=True,
                              force_collision_mesh=False)
    if not urdf.validate():
        raise ValueError("yourdfpy's validate() rejected the file")
    name = urdf_name(asset.name)
    link, joint = urdf.link_map.get(name), urdf.joint_map.get(joint_name(name))
    if link is None or link.inertial is None or joint is None:
        raise ValueError(f"no link {name!r} with <inertial> on joint {joint_name(name)!r}")
    origin = np.asarray(link.inertial.origin, dtype=float)
    T = np.asarray(joint.origin, dtype=float)
    return {
        "mass": float(link.inertial.mass), "com": origin[:3, 3] - urdf_link_offset(asset),
        "inertia": origin[:3, :3] @ np.asarray(link.inertial.inertia, dtype=float) @ origin[:3, :3].T,
        "type": joint.type, "axis": T[:3, :3] @ np.asarray(joint.axis, dtype=float), "point": T[:3, 3],
        "lower": float(joint.limit.lower), "upper": float(joint.limit.upper),
        "damping": float(joint.dynamics.damping), "friction": float(joint.dynamics.friction),
    }


JOINTED_LOADERS = {
    "mjcf": (("mujoco", _read_mujoco_jointed), ("newton", lambda a, p: _read_newton_jointed(a, p, "mjcf"))),
    "urdf": (("yourdfpy", _read_yourdfpy_jointed), ("newton", lambda a, p: _read_newton_jointed(a, p, "urdf"))),
    "usd": (("newton", lambda a, p: _read_newton_jointed(a, p, "usd")),),
}
"""Loaders of a drawer's or door's files: each returns the part's body and its joint, world frame."""


def validate_jointed_exports(asset: Asset, out_dir: Path, paths: Any, *, tolerance: float = DEFAULT_TOLERANCE) -> dict:
    """Reload a jointed asset's MJCF, URDF and USD with MuJoCo, Newton and yourdfpy; compare body and joint.

    Body: mass, COM and inertia relative errors as for free bodies. Joint: the
    type, the axis direction [rad], the distance of the loader's joint point
    from `asset.joint`'s axis line [m] (relative to the part's size), the
    limits, damping and friction (relative). Returns {loader (format): readings
    and errors}; raises ValidationError naming the file on any failure.
    """
    out_dir = Path(out_dir)
    files = {k: v for k, v in paths_from(paths, out_dir).items() if k in JOINTED_LOADERS}
    j = asset.joint
    inertial = asset.theta.inertial()
    size_m = reference_size_m(asset, out_dir)
    a, o = np.asarray(j.axis), np.asarray(j.origin)
    rel = lambda x, ref, scale=None: float(abs(x - ref) / (scale or max(abs(ref), 1e-12)))  # noqa: E731
    out = {}
    for fmt, path in files.items():
        for loader, reader in JOINTED_LOADERS[fmt]:
            try:
                r = reader(asset, path)
            except Exception as exc:  # every loader raises its own types
                raise ValidationError(path, f"{loader} could not load it: {exc}") from exc
            d = r["point"] - o
            errors = {
                "mass": rel(r["mass"], inertial.mass),
                "com": float(np.linalg.norm(r["com"] - inertial.com) / size_m),
                "inertia": float(np.linalg.norm(r["inertia"] - inertial.inertia_matrix())
                                 / np.linalg.norm(inertial.inertia_matrix())),
                "axis_rad": float(np.arccos(np.clip(r["axis"] @ a / np.linalg.norm(r["axis"]), -1, 1))),
                "axis_point": float(np.linalg.norm(d - a * (a @ d)) / size_m) if j.type == "revolute" else 0.0,
                "lower": rel(r["lower"], j.lower, max(j.upper - j.lower, 1e-12)),
                "upper": rel(r["upper"], j.upper, max(j.upper - j.lower, 1e-12)),
                "damping": rel(r["damping"], j.damping, max(abs(j.damping), 1e-9)),
                "friction": rel(r["friction"], float(asset.theta.friction.value)),
            }
            bad = {k: v for k, v in errors.items() if not v <= tolerance}
            if r["type"] != j.type or bad:
                raise ValidationError(path, f"{loader} read joint {r['type']!r} (expected {j.type!r}), "
                                            f"errors over {tolerance:g}: {bad}")
            out[f"{loader} ({fmt})"] = {"errors": errors, "type": r["type"], "friction": r["friction"],
                                        "damping": r["damping"], "limits": [r["lower"], r["upper"]]}
    return out
