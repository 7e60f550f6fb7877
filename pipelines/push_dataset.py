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

from assets.recording import PointTrack, PoseTrack, Recording, WrenchTrack

from .logs.checks import MAX_FORCE_N, MAX_POSITION_M, MAX_TORQUE_NM, LogError, bounded, drop_far_stamps, require_overlap

__all__ = ["PushTrialName", "TIP_RADIUS_M", "read_push_trial"]

TIP_RADIUS_M = 0.00475
"""Radius of the dataset's pusher ('probe4' in push-est-public probe_db.py) [m]."""

_KEYS = ("object_pose", "tip_pose", "ft_wrench")
_MAX_ROWS = 10**7
"""More rows than a day at 100 Hz: a damaged header, not a trial (the dataset's hold about 1500)."""
_EXPECTED = "expected an N x 4 array of numbers"
_MAX_YAW_RAD = 1e6
"""An unwrapped yaw of more turns than this (160 000) is no push; far beyond it a rotation is not even defined."""
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


def _json_kind(value) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "a boolean"
    return {dict: "an object", str: "a string", list: "a list"}.get(type(value), "a number")


def _json_array(path: Path, key: str, value) -> np.ndarray:
    """The numbers of a JSON value; strings, nulls and booleans are no numbers even where numpy would parse them."""
    if not isinstance(value, list):
        raise LogError(f"{path}: {key}: {_EXPECTED}, got {_json_kind(value)}")
    try:
        a = np.asarray(value)
    except ValueError:  # ragged rows
        a = None
    if a is None or a.dtype.kind not in "iuf":
        raise LogError(f"{path}: {key}: {_EXPECTED}, got a list holding non-numbers or ragged rows")
    return a.astype(float)


def _h5_kind(obj) -> str | None:
    """What keeps an HDF5 object from being a numeric dataset, or None."""
    import h5py

    if not isinstance(obj, h5py.Dataset):
        return "an HDF5 group" if isinstance(obj, h5py.Group) else f"a {type(obj).__name__}"
    if obj.shape is None:
        return "an empty dataset"
    kind = obj.dtype.kind
    if kind not in "iuf":
        return {"S": "text", "U": "text", "O": "text or references", "b": "booleans", "c": "complex numbers",
                "V": "compound records"}.get(kind, f"{obj.dtype} values")
    return None


def _load(path: Path) -> dict[str, np.ndarray]:
    if path.suffix == ".json":
        try:
            raw = json.loads(path.read_text())
        except (ValueError, RecursionError) as exc:  # bad UTF-8, bad JSON, too deeply nested or too long a number
            raise LogError(f"{path}: not valid JSON ({type(exc).__name__}: {exc})") from None
        if not isinstance(raw, dict):
            raise LogError(f"{path}: expected an object holding {list(_KEYS)}, got {_json_kind(raw)}")
        missing = [k for k in _KEYS if k not in raw]
        if missing:
            raise LogError(f"{path}: missing {missing}; a pushing trial holds {list(_KEYS)}")
        return {k: _json_array(path, k, raw[k]) for k in _KEYS}
    import h5py

    try:
        with h5py.File(path, "r") as h5:
            missing = [k for k in _KEYS if k not in h5]
            if missing:
                raise LogError(f"{path}: missing datasets {missing}; a raw pushing trial holds {list(_KEYS)} "
                               f"(found {sorted(h5)})")
            out = {}
            for k in _KEYS:
                ds = h5[k]
                if kind := _h5_kind(ds):
                    raise LogError(f"{path}: {k}: {_EXPECTED}, got {kind}")
                if len(ds.shape) != 2 or ds.shape[1] != 4 or not 2 <= ds.shape[0] <= _MAX_ROWS:
                    raise LogError(f"{path}: {k} has shape {ds.shape}, expected N x 4 with 2 <= N <= {_MAX_ROWS:g}")
                out[k] = np.asarray(ds[()], dtype=float)
            return out
    except LogError:
        raise
    except Exception as exc:  # noqa: BLE001 - h5py reports a damaged file as OSError, KeyError, ValueError, ...
        detail = " ".join(f"{type(exc).__name__}: {exc}".split())
        raise LogError(f"{path}: not a readable HDF5 file ({detail})") from None


def _ordered(path: Path, key: str, a: np.ndarray) -> np.ndarray:
    """Rows sorted by stamp, repeated stamps dropped (the raw files hold both), stray stamps dropped with a
    warning; LogError for values no trial holds."""
    if a.ndim != 2 or a.shape[1] != 4 or len(a) < 2:
        raise LogError(f"{path}: {key} has shape {a.shape}, expected N x 4 with N >= 2")
    if not np.all(np.isfinite(a)):
        raise LogError(f"{path}: {key} holds non-finite values")
    a = a[np.argsort(a[:, 0], kind="stable")]
    a = a[np.r_[True, np.diff(a[:, 0]) > 0]]
    if len(a) < 2:
        raise LogError(f"{path}: {key}: {len(a)} distinct stamp, expected at least 2")
    t, (a,) = drop_far_stamps(path, key, a[:, 0], [a])
    if key == "ft_wrench":
        bounded(path, key, "force", t, a[:, 1:3], MAX_FORCE_N, "N")
        bounded(path, key, "torque", t, a[:, 3:], MAX_TORQUE_NM, "N m")
    else:
        bounded(path, key, "position", t, a[:, 1:3], MAX_POSITION_M, "m")
        bounded(path, key, "yaw", t, a[:, 3:], _MAX_YAW_RAD, "rad")
    return a


def read_push_trial(path: Path) -> Recording:
    """One trial (.h5 or .json) as a Recording: object pose, force applied to it, tip as the contact point.

    Raises LogError naming the file for a missing file, an unknown suffix, missing
    keys, arrays that are not N x 4 numbers with two distinct stamps, non-finite
    values, a force or position beyond reason (pipelines.logs), or object and force
    streams whose stamps do not overlap. Stamps far outside the rest are dropped
    with a warning.
    """
    path = Path(path)
    if not path.is_file():
        raise LogError(f"{path}: file not found")
    if path.suffix not in (".h5", ".json"):
        raise LogError(f"{path}: a pushing-dataset trial is a .h5 or .json file")
    d = {k: _ordered(path, k, v) for k, v in _load(path).items()}
    obj, tip, ft = d["object_pose"], d["tip_pose"], d["ft_wrench"]
    require_overlap(path, "object_pose", obj[:, 0], "ft_wrench", ft[:, 0])
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
