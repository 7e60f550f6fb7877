"""Trials of the MIT pushing dataset (Yu et al., IROS 2016) as `Recording`s.

A trial is an HDF5 file (the dataset's raw `.h5`) or a JSON file with the same
three keys, each an N x 4 array of float64 on its own clock (the streams are not
synchronised; stamps are UNIX seconds):

- `object_pose`: [t_s, x_m, y_m, yaw_rad], the Vicon object frame in the robot frame;
- `tip_pose`: [t_s, x_m, y_m, yaw_rad], the pusher tip (a vertical rod, radius
  4.75 mm) in the robot frame;
- `ft_wrench`: [t_s, F_x_N, F_y_N, tau_z_Nm], the F/T reading mapped to the
  robot frame: the force ON the probe, so it is negated here to the force
  applied TO the object. Not zeroed.

Source: mcubelab/push-est-public `parse_bagfile_to_rawjson.py`, summarised in
../shared/data/mit-push/README.md, section 2. The file name carries the push
(`motion_surface=delrin_shape=rect1_a=0_v=10_i=0.000_s=0.000_t=0.698.h5`):
see `PushTrialName`.

The data are planar: poses and the contact point are placed at z = 0 (the
robot frame's table level), and the torque about z is the only moment.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from .logs import LogError, PointTrack, PoseTrack, Recording, WrenchTrack

__all__ = ["PushTrialName", "TIP_RADIUS_M", "read_push_trial"]

TIP_RADIUS_M = 0.00475
"""Radius of the dataset's pusher ('probe4' in push-est-public probe_db.py) [m]."""

_KEYS = ("object_pose", "tip_pose", "ft_wrench")
_NAME = re.compile(
    r"motion_surface=(?P<surface>[^_]+)_shape=(?P<shape>[^_]+)_a=(?P<a>[-\d.]+)_v=(?P<v>[-\d.]+)"
    r"_i=(?P<i>[-\d.]+)_s=(?P<s>[-\d.]+)_t=(?P<t>[-\d.]+)\.(h5|json)$"
)


@dataclass(frozen=True)
class PushTrialName:
    """What a trial's file name says about the push (pdproc preprocess.py parses the same keys).

    surface, shape: support material and object (an `objects.json` key).
    acceleration_mm_s2: pusher acceleration, 0 for a constant-velocity push [mm/s^2].
    velocity_mm_s: pusher speed, -1 when the push accelerates [mm/s].
    side: index of the pushed side of the object's outline; point: contact point
        along it, 0..1; angle_rad: push direction from the side's normal [rad].
    """

    surface: str
    shape: str
    acceleration_mm_s2: float
    velocity_mm_s: float
    side: int
    point: float
    angle_rad: float

    @classmethod
    def parse(cls, path: Path) -> "PushTrialName":
        m = _NAME.search(Path(path).name)
        if m is None:
            raise LogError(f"{path}: not a MIT pushing-dataset trial name "
                           "(expected motion_surface=S_shape=O_a=A_v=V_i=I_s=S_t=T.h5 or .json)")
        return cls(m["surface"], m["shape"], float(m["a"]), float(m["v"]), int(float(m["i"])), float(m["s"]),
                   float(m["t"]))


def _load(path: Path) -> dict[str, np.ndarray]:
    if path.suffix == ".json":
        try:
            raw = json.loads(path.read_text())
        except json.JSONDecodeError as exc:
            raise LogError(f"{path}: not valid JSON ({exc})") from None
        missing = [k for k in _KEYS if k not in raw]
        if missing:
            raise LogError(f"{path}: missing {missing}; a pushing trial holds {list(_KEYS)}")
        return {k: np.asarray(raw[k], dtype=float) for k in _KEYS}
    import h5py

    try:
        with h5py.File(path, "r") as h5:
            missing = [k for k in _KEYS if k not in h5]
            if missing:
                raise LogError(f"{path}: missing datasets {missing}; a raw pushing trial holds {list(_KEYS)} "
                               f"(found {sorted(h5)})")
            return {k: np.asarray(h5[k][()], dtype=float) for k in _KEYS}
    except OSError as exc:
        raise LogError(f"{path}: not a readable HDF5 file ({exc})") from None


def _ordered(path: Path, key: str, a: np.ndarray) -> np.ndarray:
    """Rows sorted by stamp, repeated stamps dropped (the raw files hold both)."""
    if a.ndim != 2 or a.shape[1] != 4 or len(a) < 2:
        raise LogError(f"{path}: {key} has shape {a.shape}, expected N x 4 with N >= 2")
    if not np.all(np.isfinite(a)):
        raise LogError(f"{path}: {key} holds non-finite values")
    a = a[np.argsort(a[:, 0], kind="stable")]
    return a[np.r_[True, np.diff(a[:, 0]) > 0]]


def read_push_trial(path: Path) -> Recording:
    """One trial (.h5 or .json) as a Recording: object pose, force applied to it, tip as the contact point.

    Raises LogError naming the file for a missing file, an unknown suffix, missing
    keys, arrays that are not N x 4, or non-finite values.
    """
    path = Path(path)
    if not path.is_file():
        raise LogError(f"{path}: file not found")
    if path.suffix not in (".h5", ".json"):
        raise LogError(f"{path}: a pushing-dataset trial is a .h5 or .json file")
    d = {k: _ordered(path, k, v) for k, v in _load(path).items()}
    obj, tip, ft = d["object_pose"], d["tip_pose"], d["ft_wrench"]
    zeros = np.zeros(len(ft))
    quat = Rotation.from_rotvec(np.c_[np.zeros((len(obj), 2)), obj[:, 3]]).as_quat()
    pose = PoseTrack(obj[:, 0], np.c_[obj[:, 1:3], np.zeros(len(obj))], quat, "world", "object", "object_pose")
    raw = WrenchTrack(ft[:, 0], np.c_[ft[:, 1:3], zeros], np.c_[zeros, zeros, ft[:, 3]], "ft_wrench", "world")
    contact = PointTrack(tip[:, 0], np.c_[tip[:, 1:3], np.zeros(len(tip))], "world", "tip_pose")
    # the reading is the reaction on the probe; its torque is about the probe, at the contact
    force = -raw.force
    p_track = np.c_[np.interp(ft[:, 0], obj[:, 0], obj[:, 1]), np.interp(ft[:, 0], obj[:, 0], obj[:, 2]), zeros]
    p_contact = np.c_[np.interp(ft[:, 0], tip[:, 0], tip[:, 1]), np.interp(ft[:, 0], tip[:, 0], tip[:, 2]), zeros]
    torque = -raw.torque + np.cross(p_contact - p_track, force)
    applied = WrenchTrack(ft[:, 0], force, torque, "ft_wrench", "world")
    t0 = min(obj[0, 0], ft[0, 0])
    t1 = max(obj[-1, 0], ft[-1, 0])
    return Recording(path, pose, applied, raw, contact, None, float(t1 - t0))
