"""What kind of motion a pose track shows (free, sliding, prismatic, revolute), chosen by BIC, and the joint.

Each candidate explains the tracked frame's poses with a number of free
parameters per sample: free 6 (anything), sliding 3 (x, y and yaw on a
horizontal support), prismatic and revolute 1 (the joint coordinate q) plus a
few global ones (axis, a point on a revolute axis, the pose at q = 0). With the
tracker's noise levels measured from the track itself, each candidate's
chi-square plus (parameter count) x ln(residual count) is its BIC, and the
smallest wins. A 1-DoF motion fits a 3- or 6-DoF model too, but pays for the
extra parameters; a free motion does not fit a joint at all.

The joint's axis, point and reference pose are then fitted by nonlinear least
squares over all samples (q of each sample a parameter too, the first pinned at
q = 0: the part sits at its scanned placement when the log starts), with their
covariance from the Gauss-Newton curvature with every q eliminated
(Schur complement).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import lil_matrix
from scipy.spatial.transform import Rotation

from assets import KINDS, Pose

__all__ = ["JointFit", "KindDetection", "detect_kind", "joint_coordinates"]

_JOINT_KINDS = ("prismatic", "revolute")


@dataclass(frozen=True)
class JointFit:
    """A joint found from a pose track; world frame.

    axis: unit, +q along it (right-hand rule for revolute), sign chosen so the
    observed travel is mostly positive. axis_std_rad: 1-sigma angle of the axis
    direction's error. origin [m]: a point on the axis (revolute: the one
    nearest the tracked frame at q = 0; prismatic: the tracked origin at q = 0).
    origin_std_m [3]: 1-sigma per world axis (revolute; zero for prismatic, where
    any point will do). tracked_at_zero: the tracked frame at q = 0. t_s, q:
    the joint coordinate at each pose sample [m or rad].
    """

    type: str
    axis: np.ndarray
    axis_std_rad: float
    origin: np.ndarray
    origin_std_m: np.ndarray
    tracked_at_zero: Pose
    t_s: np.ndarray
    q: np.ndarray
    rms_position_m: float
    rms_rotation_rad: float

    def tracked_position(self, q: np.ndarray) -> np.ndarray:
        """The tracked frame's origin [m, world] at joint coordinates q, shape (..., 3)."""
        q = np.asarray(q, dtype=float)
        p_ref = np.asarray(self.tracked_at_zero.position)
        if self.type == "prismatic":
            return p_ref + q[..., None] * self.axis
        R_q = Rotation.from_rotvec(np.outer(q.reshape(-1), self.axis))
        return (self.origin + R_q.apply(p_ref - self.origin)).reshape(*q.shape, 3)

    def to_json(self) -> dict:
        return {
            "type": self.type, "axis": self.axis.tolist(), "axis_std_rad": self.axis_std_rad,
            "origin": self.origin.tolist(), "origin_std_m": self.origin_std_m.tolist(),
            "observed_travel": [float(self.q.min()), float(self.q.max())],
            "rms_position_m": self.rms_position_m, "rms_rotation_rad": self.rms_rotation_rad,
            "tracked_at_zero": self.tracked_at_zero.to_json(),
        }

    @staticmethod
    def from_json(d: dict) -> "JointFit":
        """The joint `to_json` wrote; its samples are not recorded, so t_s is empty and q the observed travel."""
        return JointFit(d["type"], np.asarray(d["axis"], float), float(d["axis_std_rad"]),
                        np.asarray(d["origin"], float), np.asarray(d["origin_std_m"], float),
                        Pose.from_json(d["tracked_at_zero"]), np.zeros(0),
                        np.asarray(d["observed_travel"], float), float(d["rms_position_m"]),
                        float(d["rms_rotation_rad"]))


@dataclass(frozen=True)
class KindDetection:
    """The chosen kind, every candidate's BIC (lower is better), the noise used, and the joint if jointed."""

    kind: str
    bic: dict
    position_sigma_m: float
    rotation_sigma_rad: float
    joint: JointFit | None
    forced: bool

    def to_json(self) -> dict:
        return {
            "kind": self.kind, "forced_by_user": self.forced, "bic": self.bic,
            "noise": {"position_m": self.position_sigma_m, "rotation_rad": self.rotation_sigma_rad},
            "joint": None if self.joint is None else self.joint.to_json(),
        }


def _perp_basis(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    e1 = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(a, e1)


class _OneDofModel:
    """Poses of the tracked frame as a function of global parameters g and per-sample q.

    g = (axis tilt u, v, [revolute: point offsets s, w], reference position (3), reference rotation vector (3)),
    all as increments from the start values so the least-squares problem starts at zero.
    """

    def __init__(self, joint_type: str, axis0, point0, p_ref0, R_ref0: Rotation):
        self.revolute = joint_type == "revolute"
        self.a0 = np.asarray(axis0, float) / np.linalg.norm(axis0)
        self.e1, self.e2 = _perp_basis(self.a0)
        self.c0 = np.asarray(point0, float)
        self.p_ref0 = np.asarray(p_ref0, float)
        self.R_ref0 = R_ref0
        self.global_count = 10 if self.revolute else 8

    def unpack(self, g):
        a = self.a0 + g[0] * self.e1 + g[1] * self.e2
        a = a / np.linalg.norm(a)
        k = 2
        c = None
        if self.revolute:
            c = self.c0 + g[2] * self.e1 + g[3] * self.e2
            k = 4
        p_ref = self.p_ref0 + g[k:k + 3]
        R_ref = Rotation.from_rotvec(g[k + 3:k + 6]) * self.R_ref0
        return a, c, p_ref, R_ref

    def predict(self, g, q):
        a, c, p_ref, R_ref = self.unpack(g)
        if self.revolute:
            R_q = Rotation.from_rotvec(np.outer(q, a))
            return c + R_q.apply(p_ref - c), R_q * R_ref
        return p_ref + np.outer(q, a), Rotation.concatenate([R_ref] * len(q))


def _residuals(model: _OneDofModel, g, q, position, rotation: Rotation, sp: float, sr: float) -> np.ndarray:
    p, R = model.predict(g, q)
    return np.hstack([(position - p) / sp, (rotation * R.inv()).as_rotvec() / sr]).ravel()


def _fit_one_dof(joint_type: str, position, rotation: Rotation, sp: float, sr: float):
    """Least-squares joint fit; returns (model, g, q, chi2, covariance of g)."""
    N = len(position)
    R0 = rotation[0]
    if joint_type == "revolute":
        rv = (rotation * R0.inv()).as_rotvec()
        axis = np.linalg.eigh(rv.T @ rv)[1][:, -1]
        q0 = rv @ axis
        # (I - R_k) c + R_k p_ref = p_k is linear in c given R_k; the point along the axis is free
        R_q = Rotation.from_rotvec(np.outer(q0, axis)).as_matrix()
        A = np.concatenate([np.eye(3) - R_q, R_q], axis=2).reshape(-1, 6)
        sol = np.linalg.lstsq(A, position.reshape(-1), rcond=None)[0]
        c = sol[:3] - axis * (axis @ (sol[:3] - position[0]))
        model = _OneDofModel("revolute", axis, c, position[0], R0)
    else:
        centred = position - position.mean(0)
        axis = np.linalg.eigh(centred.T @ centred)[1][:, -1]
        q0 = (position - position[0]) @ axis
        model = _OneDofModel("prismatic", axis, position[0], position[0], R0)
    G = model.global_count

    def fun(x):
        return _residuals(model, x[:G], np.concatenate([[0.0], x[G:]]), position, rotation, sp, sr)

    sparsity = lil_matrix((6 * N, G + N - 1), dtype=int)
    sparsity[:, :G] = 1
    for k in range(1, N):
        sparsity[6 * k:6 * k + 6, G + k - 1] = 1
    x0 = np.concatenate([np.zeros(G), q0[1:]])
    res = least_squares(fun, x0, jac_sparsity=sparsity, method="trf", x_scale="jac", xtol=1e-10, ftol=1e-10,
                        max_nfev=40)
    J = res.jac.tocsc()
    Jg, Jq = J[:, :G].toarray(), J[:, G:]
    A = Jg.T @ Jg
    B = np.asarray((Jq.T @ Jg)).T
    D = np.asarray(Jq.multiply(Jq).sum(axis=0)).ravel()
    chi2 = float(res.fun @ res.fun)
    s2 = chi2 / max(1, len(res.fun) - len(res.x))
    schur = A - (B / D) @ B.T
    cov = s2 * np.linalg.pinv(schur)
    return model, res.x[:G], np.concatenate([[0.0], res.x[G:]]), chi2, cov


def _chi2_sliding(position, rotation: Rotation, sp: float, sr: float) -> float:
    """Planar motion on a horizontal support: height and tilt constant, x, y, yaw free per sample."""
    z = position[:, 2]
    R_ref = rotation[0]
    rel = rotation * R_ref.inv()
    yaw = rel.as_rotvec()[:, 2]
    tilt = (Rotation.from_rotvec(np.outer(-yaw, [0.0, 0.0, 1.0])) * rel).as_rotvec()
    tilt -= tilt.mean(0)
    return float(np.sum(((z - z.mean()) / sp) ** 2) + np.sum((tilt / sr) ** 2))


def _joint_fit(joint_type, model: _OneDofModel, g, q, cov, t_s, position, rotation) -> JointFit:
    a, c, p_ref, R_ref = model.unpack(g)
    p, R = model.predict(g, q)
    if np.mean(q) < 0:  # opening is +q
        a, q = -a, -q
    axis_cov = cov[:2, :2]
    axis_std = float(np.sqrt(max(np.trace(axis_cov), 0.0)))
    if joint_type == "revolute":
        # nearest point of the axis to the tracked frame at q = 0
        origin = c + a * (a @ (p_ref - c))
        Epoint = np.stack([model.e1, model.e2], axis=1)
        origin_cov = Epoint @ cov[2:4, 2:4] @ Epoint.T
        origin_std = np.sqrt(np.maximum(np.diag(origin_cov), 0.0))
    else:
        origin, origin_std = p_ref, np.zeros(3)
    return JointFit(
        type=joint_type, axis=a, axis_std_rad=axis_std, origin=origin, origin_std_m=origin_std,
        tracked_at_zero=Pose(tuple(p_ref), tuple(R_ref.as_quat())), t_s=np.asarray(t_s), q=q,
        rms_position_m=float(np.sqrt(np.mean(np.sum((position - p) ** 2, 1)))),
        rms_rotation_rad=float(np.sqrt(np.mean(np.sum((rotation * R.inv()).as_rotvec() ** 2, 1)))),
    )


def detect_kind(recording, kind: str | None = None, max_samples: int = 400) -> KindDetection:
    """Choose the kind of `recording`'s tracked-frame motion by BIC, and fit the joint for jointed kinds.

    kind: a kind from assets.KINDS forces the choice (`--kind`); the BIC of
    every candidate is still reported. max_samples: the track is thinned evenly
    to at most this many poses for the fit (noise levels use all of them).
    """
    from .noise import recording_noise_levels

    if kind is not None and kind not in KINDS:
        raise ValueError(f"--kind: expected one of {KINDS}, got {kind!r}")
    pose = recording.pose
    if len(pose.t_s) < 20:
        raise ValueError(f"{recording.path}: {len(pose.t_s)} pose samples; need at least 20 to tell the kind of motion")
    noise = recording_noise_levels(recording)
    sp, sr = max(noise.position_m, 1e-6), max(noise.rotation_rad, 1e-6)
    step = max(1, int(np.ceil(len(pose.t_s) / max_samples)))
    t_s, position = pose.t_s[::step], pose.position[::step]
    rotation = Rotation.from_quat(pose.quat_xyzw[::step])
    N = len(t_s)
    n = 6 * N
    ln_n = np.log(n)

    fits = {}
    bic = {"free": 6 * N * ln_n, "sliding": _chi2_sliding(position, rotation, sp, sr) + (3 * N + 4) * ln_n}
    for joint_type in _JOINT_KINDS:
        model, g, q, chi2, cov = _fit_one_dof(joint_type, position, rotation, sp, sr)
        fits[joint_type] = (model, g, q, cov)
        bic[joint_type] = chi2 + (model.global_count + N - 1) * ln_n
    chosen = kind or min(bic, key=bic.get)
    joint = None
    if chosen in _JOINT_KINDS:
        model, g, q, cov = fits[chosen]
        joint = _joint_fit(chosen, model, g, q, cov, t_s, position, rotation)
        # q at every pose sample, not only the thinned ones
        joint = JointFit(**{**joint.__dict__, "t_s": pose.t_s, "q": joint_coordinates(joint, pose)})
    return KindDetection(chosen, {k: float(v) for k, v in bic.items()}, sp, sr, joint, kind is not None)


def joint_coordinates(joint: JointFit, pose) -> np.ndarray:
    """q [m or rad] of each sample of a pose track on a known joint: the least-squares q per sample
    (position error weighted like a rotation error at the tracked frame's lever arm)."""
    a = joint.axis
    p_ref = np.asarray(joint.tracked_at_zero.position)
    R_ref = Rotation.from_quat(joint.tracked_at_zero.quaternion_xyzw)
    position = np.asarray(pose.position)
    rotation = Rotation.from_quat(pose.quat_xyzw)
    if joint.type == "prismatic":
        return (position - p_ref) @ a
    q = (rotation * R_ref.inv()).as_rotvec() @ a
    r0 = p_ref - joint.origin
    for _ in range(3):  # Gauss-Newton on the position residual; the rotation start is already close
        R_q = Rotation.from_rotvec(np.outer(q, a))
        r = R_q.apply(r0)
        err = position - joint.origin - r
        dp = np.cross(a, r)
        q = q + np.sum(err * dp, 1) / np.maximum(np.sum(dp * dp, 1), 1e-12)
    return q
