"""Fuzz targets for the recording readers and asset.json: `read_recording` (MCAP), `read_push_trial` (the MIT
pushing dataset's .json and .h5 trials) and `read_asset`.

Each seed is written on the fly. Beside byte-level damage, the MCAP target rewrites its messages with odd
stamps (zero, negative, 2^31 s), odd values (NaN, infinities, 1e300), odd frame ids, lost and repeated
messages and JSON messages of the wrong shape; the trial targets change their arrays' types and shapes
(for HDF5: groups, text, empty and complex datasets, dangling links). A reader passes when it reads the
input or raises the project's own error with a one-line message that starts with the file's path.
"""

from __future__ import annotations

import copy
import io
import json
import warnings
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path
from typing import Callable

import numpy as np

from benchmarks.fuzz import ODD_VALUES, FuzzTarget, mutate_bytes, mutate_json, mutate_json_doc

PUSH_TRIAL = "motion_surface=abs_shape=rect1_a=0_v=10_i=0.000_s=0.000_t=0.698"
"""A trial file's name as the dataset spells it (the reader parses it)."""

_ODD_FLOATS = (float("nan"), float("inf"), -float("inf"), 1e300, -1e300, 0.0, -0.0, 5e-324, 1e6, -1e5)
_ODD_SECS = (0, 1, -1, 2**31 - 1, -(2**31), 10**9, 1_700_000_000)
_ODD_NANOSECS = (0, 1, 999_999_999, 10**9, 2**32 - 1)
_ODD_FRAMES = ("", "/", "world", "/world", "gripper", "ft_sensor", "nowhere", "x" * 300, "/tf")


def _checked(read: Callable[[Path], object], errors: tuple[type[BaseException], ...]) -> Callable:
    """`read` with warnings and printed output silenced (mcap_ros2 prints the schemas it cannot parse), whose
    errors must say '<path>: <problem>' on one line."""
    def checked(path: Path) -> object:
        with warnings.catch_warnings(), redirect_stdout(io.StringIO()), redirect_stderr(io.StringIO()):
            warnings.simplefilter("ignore")
            try:
                return read(path)
            except errors as exc:
                text = str(exc)
                if not text.startswith(f"{path}: ") or "\n" in text:
                    raise AssertionError(f"message not '<file>: <problem>' on one line: {text[:200]!r}") from exc
                raise

    return checked


# --------------------------------------------------------------------------
# MCAP


def _stamp(t_s: float) -> dict:
    ns = int(round(t_s * 1e9))
    return {"sec": ns // 10**9, "nanosec": ns % 10**9}


def _recording_messages() -> list[list]:
    """[topic, type, message] of a valid 0.3 s trial, in time order: a gripper turning about z, a wrist
    sensor held to it by /tf_static, a contact point, joint states, and a second pose topic, JSON at half the
    rate (so that the gripper's is the one chosen)."""
    t0 = 100.0
    sensor = {"header": {"stamp": _stamp(t0), "frame_id": "gripper"}, "child_frame_id": "ft_sensor",
              "transform": {"translation": {"x": 0.0, "y": 0.0, "z": 0.05},
                            "rotation": {"x": 1.0, "y": 0.0, "z": 0.0, "w": 0.0}}}
    out = [["/tf_static", "tf2_msgs/msg/TFMessage", {"transforms": [sensor]}]]
    for k in range(30):
        t = t0 + 0.01 * k
        turn = 0.05 * k  # rad about z
        out.append(["/tracker/pose", "geometry_msgs/msg/TransformStamped", {
            "header": {"stamp": _stamp(t), "frame_id": "world"}, "child_frame_id": "gripper",
            "transform": {"translation": {"x": 0.4 + 0.001 * k, "y": 0.0, "z": 0.1},
                          "rotation": {"x": 0.0, "y": 0.0, "z": np.sin(turn / 2), "w": np.cos(turn / 2)}}}])
        out.append(["/ft_sensor/wrench", "geometry_msgs/msg/WrenchStamped", {
            "header": {"stamp": _stamp(t + 0.004), "frame_id": "ft_sensor"},
            "wrench": {"force": {"x": 1.0, "y": -0.5, "z": 9.8}, "torque": {"x": 0.01, "y": 0.0, "z": 0.02 * k}}}])
        out.append(["/contact/point", "geometry_msgs/msg/PointStamped", {
            "header": {"stamp": _stamp(t + 0.002), "frame_id": "world"},
            "point": {"x": 0.45, "y": 0.0, "z": 0.1}}])
        out.append(["/joint_states", "sensor_msgs/msg/JointState", {
            "header": {"stamp": _stamp(t), "frame_id": ""}, "name": ["j1", "j2"],
            "position": [0.1 * k, -0.1 * k], "velocity": [10.0, -10.0], "effort": []}])
        if k % 2:
            continue
        out.append(["/object/pose", "foxglove.PoseInFrame", {
            "timestamp": {"sec": int(t), "nsec": int(round((t % 1) * 1e9))}, "frame_id": "world",
            "pose": {"position": {"x": 0.5, "y": 0.0, "z": 0.1}, "orientation": {"x": 0, "y": 0, "z": 0, "w": 1}}}])
    return out


def _write_mcap(path: Path, messages: list[list], compressed: bool, crcs: bool) -> None:
    """Messages as given: CDR for ROS 2 types, JSON for foxglove ones; log time from the stamp when it fits."""
    from mcap.writer import CompressionType, Writer
    from mcap_ros2._dynamic import serialize_dynamic

    from pipelines.synth.recording import MSGDEFS

    with open(path, "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD if compressed else CompressionType.NONE, enable_crcs=crcs)
        w.start(profile="ros2", library="twin fuzz")
        channels: dict[str, tuple[int, Callable]] = {}
        for i, (topic, type_, msg) in enumerate(messages):
            if topic not in channels:
                if type_ in MSGDEFS:
                    sid = w.register_schema(type_, "ros2msg", MSGDEFS[type_].encode())
                    encode = serialize_dynamic(type_, MSGDEFS[type_])[type_]
                    channels[topic] = (w.register_channel(topic, "cdr", sid), encode)
                else:
                    sid = w.register_schema(type_, "jsonschema", b"{}")
                    channels[topic] = (w.register_channel(topic, "json", sid),
                                       lambda m: json.dumps(m, allow_nan=True).encode())
            cid, encode = channels[topic]
            stamp = _header_stamp(msg)
            log_ns = max(0, stamp["sec"] * 10**9 + stamp["nanosec"]) if stamp else 10**11 + i
            w.add_message(cid, log_time=log_ns, data=encode(msg), publish_time=0, sequence=i)
        w.finish()


def _header_stamp(msg) -> dict | None:
    """The header's stamp of a ROS 2 message (JSON messages here have none)."""
    header = msg.get("header") if isinstance(msg, dict) else None
    return header["stamp"] if isinstance(header, dict) else None


def _leaves(node, out: list) -> list:
    """(container, key) of every number and string under a message."""
    items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
    for k, v in items:
        if isinstance(v, (dict, list)):
            _leaves(v, out)
        else:
            out.append((node, k))
    return out


def _odd_message(msg: dict, json_encoded: bool, rng: np.random.Generator):
    """The message with one field changed to an odd value its encoding can still carry."""
    if json_encoded and rng.random() < 0.5:
        return mutate_json_doc(msg, rng)
    leaves = _leaves(msg, [])
    if not leaves:  # a JSON message already replaced by a bare value
        return msg
    container, key = leaves[int(rng.integers(0, len(leaves)))]
    value = container[key]
    if json_encoded and rng.random() < 0.3:
        container[key] = copy.deepcopy(ODD_VALUES[int(rng.integers(0, len(ODD_VALUES)))])
    elif key == "sec":
        container[key] = _ODD_SECS[int(rng.integers(0, len(_ODD_SECS)))]
    elif key in ("nanosec", "nsec"):
        container[key] = _ODD_NANOSECS[int(rng.integers(0, len(_ODD_NANOSECS)))] % 2**32
    elif isinstance(value, str):
        container[key] = _ODD_FRAMES[int(rng.integers(0, len(_ODD_FRAMES)))]
    else:
        container[key] = _ODD_FLOATS[int(rng.integers(0, len(_ODD_FLOATS)))]
    return msg


def _mutate_messages(messages: list[list], rng: np.random.Generator) -> list[list]:
    """One to eight message-level edits: odd fields, whole streams restamped, messages lost or repeated."""
    for _ in range(int(rng.integers(1, 9))):
        if not messages:
            break
        op = rng.random()
        i = int(rng.integers(0, len(messages)))
        topic, type_, msg = messages[i]
        if op < 0.55:
            messages[i][2] = _odd_message(msg, type_.startswith("foxglove"), rng)
        elif op < 0.65:  # a whole stream shifted onto another clock, or scaled into other units
            shift, scale = float(rng.choice([0.0, 50.0, -99.0, 1e9])), float(rng.choice([1.0, 1e3, 1e-9, -1.0]))
            for m in messages:
                stamp = _header_stamp(m[2]) if m[0] == topic else None
                if stamp:
                    t = min(max((stamp["sec"] + stamp["nanosec"] * 1e-9) * scale + shift, -(2**31)), 2**31 - 1)
                    stamp.update(sec=int(np.floor(t)), nanosec=int((t - np.floor(t)) * 1e9) % 10**9)
        elif op < 0.75:
            del messages[i]
        elif op < 0.85:
            messages.insert(i, copy.deepcopy(messages[i]))
        elif op < 0.92:  # a stream lost, or all but one of it
            keep = i if rng.random() < 0.5 else -1
            messages = [m for j, m in enumerate(messages) if m[0] != topic or j == keep]
        else:  # a stream renamed, onto another's topic or the frames'
            new = str(rng.choice(["/tf", "/tf_static", "/tracker/pose", "/ft_sensor/wrench", "/x"]))
            for m in messages:
                if m[0] == topic and (new not in {n[0] for n in messages} or m[1] == type_):
                    m[0] = new
    return messages


def _mcap_seed(folder: Path) -> Path:
    path = folder / "trial.mcap"
    _write_mcap(path, _recording_messages(), compressed=False, crcs=False)
    return path


def _mutate_mcap(path: Path, rng: np.random.Generator) -> None:
    """Byte damage to the uncompressed seed (so that it reaches the payloads) half the time; else the
    messages rewritten, compressed or not, sometimes damaged as well."""
    if rng.random() < 0.5:
        mutate_bytes(path, rng)
        return
    messages = _mutate_messages(_recording_messages(), rng)
    _write_mcap(path, messages, compressed=bool(rng.random() < 0.3), crcs=bool(rng.random() < 0.5))
    if rng.random() < 0.15:
        mutate_bytes(path, rng)


# --------------------------------------------------------------------------
# MIT pushing trials


def _push_arrays(n: int = 40) -> dict[str, np.ndarray]:
    """A 1 s push along x at 10 mm/s, each stream on its own clock, as the dataset holds them."""
    s = np.linspace(0.0, 1.0, n)
    t, zero = 1.46e9 + s, np.zeros(n)
    return {"object_pose": np.c_[t, 0.3 + 0.01 * s, 0.01 * s, 0.05 * s],
            "tip_pose": np.c_[t + 0.003, 0.25 + 0.01 * s, zero, zero],
            "ft_wrench": np.c_[t + 0.001, np.full(n, -1.5), 0.1 * s, 0.01 * s]}


def _push_json_seed(folder: Path) -> Path:
    path = folder / f"{PUSH_TRIAL}.json"
    path.write_text(json.dumps({k: v.tolist() for k, v in _push_arrays().items()}))
    return path


def _odd_array(rng: np.random.Generator, n: int = 40):
    """A value in place of an N x 4 array: wrong shapes, too few rows, odd stamps or values."""
    a = _push_arrays(n)["object_pose"]
    choice = int(rng.integers(0, 9))
    if choice == 0:
        return a[:, :3]
    if choice == 1:
        return a[: int(rng.integers(0, 3))]
    if choice == 2:
        return a.T
    if choice == 3:
        return a[:, :, None]
    if choice == 4:
        return a[:, 0]
    if choice == 5:  # repeated stamps
        return np.c_[np.full(n, a[0, 0]), a[:, 1:]]
    if choice == 6:  # stamps reversed
        return a[::-1]
    b = a.copy()
    b[int(rng.integers(0, n)), int(rng.integers(0, 4))] = float(rng.choice(_ODD_FLOATS))
    return b


def _mutate_push_json(path: Path, rng: np.random.Generator) -> None:
    """Half the time the generic JSON mutations; else a key's array replaced by an odd value or array."""
    if rng.random() < 0.5:
        mutate_json(path, rng)
        return
    doc = json.loads(path.read_text())
    key = str(rng.choice(list(doc)))
    if rng.random() < 0.3:
        doc[key] = ODD_VALUES[int(rng.integers(0, len(ODD_VALUES)))]
    else:
        doc[key] = _odd_array(rng).tolist()
    path.write_text(json.dumps(doc, allow_nan=True))


def _push_h5_seed(folder: Path) -> Path:
    import h5py

    path = folder / f"{PUSH_TRIAL}.h5"
    with h5py.File(path, "w") as h5:
        for k, v in _push_arrays().items():
            h5[k] = v
    return path


def _mutate_push_h5(path: Path, rng: np.random.Generator) -> None:
    """One to three structural edits with h5py (groups, text, empties, odd dtypes and shapes, links, a huge
    declared dataset); a quarter of the time byte damage instead."""
    import h5py

    if rng.random() < 0.25:
        mutate_bytes(path, rng)
        return
    with h5py.File(path, "r+") as h5:
        for _ in range(int(rng.integers(1, 4))):
            key = str(rng.choice(["object_pose", "tip_pose", "ft_wrench"]))
            if key in h5:
                del h5[key]
            op = int(rng.integers(0, 13))
            if op == 0:
                h5.create_group(key).create_dataset("inner", data=np.zeros((3, 4)))
            elif op == 1:
                h5[key] = np.array([b"1.0", b"2.0", b"x", b""] * 10)
            elif op == 2:
                h5.create_dataset(key, data=h5py.Empty("f8"))
            elif op == 3:
                h5[key] = _push_arrays()["tip_pose"].astype(complex)
            elif op == 4:
                h5[key] = _push_arrays()["tip_pose"] > 0.5
            elif op == 5:
                h5[key] = np.zeros(40, dtype=[("t", "f8"), ("x", "f8"), ("y", "f8"), ("yaw", "f8")])
            elif op == 6:
                h5[key] = h5py.SoftLink("/nowhere")
            elif op == 7:
                h5[key] = h5py.ExternalLink("missing.h5", "/data")
            elif op == 8:
                h5.create_dataset(key, data=3.5)
            elif op == 9:
                with np.errstate(over="ignore", invalid="ignore"):  # stamps do not fit small types: fine here
                    h5[key] = _push_arrays()["tip_pose"].astype(rng.choice(["i1", "u8", "f2", "f4"]))
            elif op == 10:
                h5.create_dataset(key, shape=(0, 4), dtype="f8")
            elif op == 11:  # declared, never written: 3.2 GB to whoever reads it whole
                h5.create_dataset(key, shape=(10**8, 4), dtype="f8", chunks=(1024, 4))
            else:
                h5[key] = _odd_array(rng)


# --------------------------------------------------------------------------
# asset.json


def _asset_seed(folder: Path) -> Path:
    """A revolute part with every optional field of asset.json filled."""
    from assets import Asset, Effect, Estimate, Fit, FitMetrics, Geometry, Joint, Material, Pose, Theta, write_asset

    inertia = ((0.05, 0.001, 0.0), (0.001, 0.04, 0.0), (0.0, 0.0, 0.02))
    theta = Theta(
        mass=Estimate(2.5, 0.1, interval95=(2.3, 2.7), prior={"mass_kg": 2.4}),
        com=Estimate((0.2, 0.0, 0.3), (0.01, 0.01, 0.01), source="prior",
                     interval95=((0.18, -0.02, 0.28), (0.22, 0.02, 0.32))),
        inertia=Estimate(inertia, tuple(tuple(abs(x) * 0.1 for x in row) for row in inertia)),
        friction=Estimate(0.3, 0.05, interval95=(0.2, 0.4)),
        determined=(("axis_inertia", Estimate(0.21, 0.01)), ("gravity_moment", Estimate(0.5, 0.02))),
    )
    asset = Asset(
        name="door", kind="revolute", placement=Pose((0.1, 0.2, 0.3), (0.0, 0.0, 0.6, 0.8)), theta=theta,
        geometry=Geometry("meshes/visual.obj", ("meshes/collision_000.obj", "meshes/collision_001.obj"),
                          "meshes/base.obj"),
        material=Material("wood", 600.0, 0.4, 0.1, text="oak veneer", source="hint", match_score=0.8),
        joint=Joint("revolute", (0.0, 0.0, 1.0), (0.5, 0.0, 0.0), -0.1, 1.6, damping=0.02, stiffness=0.5,
                    spring_ref=0.1, axis_std_rad=0.01, origin_std_m=(0.001, 0.001, 0.0)),
        effects=(Effect("spring", {"k": 0.5, "q0": 0.1}, {"gain": 0.3}), Effect("viscous_damping", {"b": 0.1})),
        fit=Fit(FitMetrics(0.01, 0.02, 0.5), FitMetrics(0.002, 0.004, 0.1), 0.5),
        unexplained=({"summary": "late bump", "where": {"t_s": [1.0, 1.2]}, "share": 0.1},),
        flags=({"parameter": "mass", "problem": "outside its prior bounds"},),
        files={"urdf": "door.urdf", "mjcf": "door.xml"}, provenance={"config": {"kind": None}},
    )
    path = folder / "asset.json"
    write_asset(asset, path)
    return path


# --------------------------------------------------------------------------
# the targets


def _targets() -> dict[str, FuzzTarget]:
    from assets import AssetError, read_asset
    from pipelines.logs import LogError, read_recording
    from pipelines.push_dataset import read_push_trial

    def target(name, seed, mutate, read, error) -> FuzzTarget:
        return FuzzTarget(name, seed, mutate, _checked(read, (error,)), (error,))

    return {
        "mcap": target("mcap", _mcap_seed, _mutate_mcap, read_recording, LogError),
        "push-json": target("push-json", _push_json_seed, _mutate_push_json, read_push_trial, LogError),
        "push-h5": target("push-h5", _push_h5_seed, _mutate_push_h5, read_push_trial, LogError),
        "asset-json": target("asset-json", _asset_seed, mutate_json, read_asset, AssetError),
    }


LOG_TARGETS: dict[str, FuzzTarget] = _targets()
"""The recording and asset.json readers under fuzzing, by name."""
