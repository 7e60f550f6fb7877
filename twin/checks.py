"""What a build can be told is wrong within its first second, before any reconstruction.

Everything here is cheap: paths exist and are of the right kind, OUT can be written without losing a
user's file, option values are in range, and the recordings hold the topics asked for (read from the
MCAP summary, not the messages). The slow checks (pixels, messages, meshes) stay with the stages.
"""

from __future__ import annotations

import math
from pathlib import Path

from pipelines.meshes import MESH_SUFFIXES, MESH_UNITS

RECORDING_SUFFIXES = (".mcap", ".h5", ".json")
ROLES = ("pose", "wrench", "contact", "joint")
FRAME_ROLES = ("wrench", "contact")


class InputError(ValueError):
    """An input or option the build cannot use; the message names the file or option."""


def check_recording_path(path: Path, what: str = "--logs") -> None:
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: recording not found ({what})")
    if path.is_dir():
        if len(list(path.glob("*.mcap"))) != 1:
            raise InputError(f"{path}: a folder given to {what} must be a rosbag2 folder holding one .mcap file")
        return
    if path.suffix.lower() not in RECORDING_SUFFIXES:
        raise InputError(f"{path}: not a recording ({what} takes .mcap, or a pushing-dataset .h5/.json trial)")


def check_source(source: Path, scans: tuple[Path, ...], mesh_units: str | None) -> None:
    source = Path(source)
    if not source.exists():
        raise InputError(f"{source}: SOURCE not found (a scan folder or a mesh file {', '.join(MESH_SUFFIXES)})")
    if source.is_dir():
        if not (source / "transforms.json").is_file() and not any(source.glob("*.depth.png")):
            raise InputError(f"{source}: not a scan folder (no transforms.json, no frame-XXXXXX.depth.png)")
        if mesh_units is not None:
            raise InputError(f"--mesh-units {mesh_units}: only for a mesh SOURCE; {source} is a scan folder")
    elif source.suffix.lower() not in MESH_SUFFIXES:
        raise InputError(f"{source}: not a scan folder or a mesh file ({', '.join(MESH_SUFFIXES)})")
    for scan in scans:
        if not Path(scan).is_dir() or not source.is_dir():
            raise InputError(f"{scan}: --scan needs scan folders (SOURCE and each --scan), not mesh files")


def check_options(config) -> None:
    """Values the command line accepts by type but the build cannot use."""
    if not config.logs:
        raise InputError("--logs: no recording given; pass --logs TRIAL.mcap")
    if config.vlm and not config.vlm_model:
        raise InputError(f"--vlm {config.vlm}: needs --vlm-model NAME")
    if not (math.isfinite(config.window_s) and 0.005 <= config.window_s <= 10):
        raise InputError(f"--window-s {config.window_s}: expected a window of 0.005 to 10 s")
    if config.max_iterations < 1:
        raise InputError(f"--max-iterations {config.max_iterations}: expected at least 1")
    if not (math.isfinite(config.push_min_speed_m_s) and 0 <= config.push_min_speed_m_s < 10):
        raise InputError(f"--push-min-speed {config.push_min_speed_m_s}: expected 0 to 10 m/s")
    if config.mesh_units is not None and config.mesh_units not in MESH_UNITS:
        raise InputError(f"--mesh-units {config.mesh_units}: expected one of {', '.join(MESH_UNITS)}")
    if config.mass_kg is not None:
        mass, std = config.mass_kg
        if not (math.isfinite(mass) and 0 < mass < 1e4):
            raise InputError(f"--mass {mass}: expected a mass in kg, above 0 and below 10 t")
        if not (math.isfinite(std) and 0 < std < mass):
            raise InputError(f"--mass {mass} {std}: its uncertainty must be above 0 and below the mass")
    if config.wrench_rotation_xyzw is not None:
        q = config.wrench_rotation_xyzw
        if not all(math.isfinite(v) for v in q) or abs(math.sqrt(sum(v * v for v in q)) - 1) > 1e-3:
            raise InputError(f"--wrench-rotation {' '.join(map(str, q))}: expected a unit quaternion x y z w")
    for flag, pairs, roles in (("--topic", config.topics, ROLES), ("--frame", config.frames, FRAME_ROLES)):
        for role, value in pairs:
            if role not in roles:
                raise InputError(f"{flag} {role}={value}: unknown role {role!r}; expected one of {', '.join(roles)}")


def check_topics(path: Path, topics: tuple[tuple[str, str], ...]) -> None:
    """Each --topic names a topic the MCAP file has (from its summary; files without one are left to the reader)."""
    if not topics:
        return
    path = Path(path)
    if path.is_dir():
        path = next(path.glob("*.mcap"))
    if path.suffix.lower() != ".mcap":
        raise InputError(f"{path}: --topic applies to MCAP recordings; a pushing-dataset trial fixes its streams")
    from mcap.reader import make_reader

    try:
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
    except Exception:  # noqa: BLE001 - a damaged file is the reader's to report, with its reason
        return
    if summary is None:
        return
    present = sorted({c.topic for c in summary.channels.values()})
    for role, topic in topics:
        if topic not in present:
            raise InputError(f"{path}: no topic {topic} (--topic {role}={topic}); it has {', '.join(present)}")


def check_build(config) -> Path:
    """Every cheap check of a build's inputs, in the order a user would fix them; returns the absolute OUT."""
    from twin.output import check_output

    check_options(config)
    check_source(config.source, config.scans, config.mesh_units)
    if config.material is not None:
        from assets.materials import material_range

        try:
            material_range(config.material)
        except ValueError as exc:
            raise InputError(f"--material: {exc}") from None
    for path in config.logs:
        check_recording_path(path)
    if config.holdout is not None:
        check_recording_path(config.holdout, "--holdout")
    if config.base_mesh is not None:
        base = Path(config.base_mesh)
        if not base.exists():
            raise InputError(f"{base}: base mesh not found (--base-mesh)")
        if not base.is_file() or base.suffix.lower() not in MESH_SUFFIXES:
            raise InputError(f"{base}: --base-mesh needs a mesh file ({', '.join(MESH_SUFFIXES)})")
    for path in (*config.logs, *((config.holdout,) if config.holdout else ())):
        check_topics(path, config.topics)
    return check_output(config.output, config.force)
