"""`validate_exports`: every exported file read by its loaders and compared with the asset."""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from assets import Asset

from .loaders import LOADERS, Reader, Reading
from .report import DEFAULT_TOLERANCE, LoaderCheck, ValidationError, ValidationReport


_COM_FLOOR_M = 1e-9


def reference_size_m(asset: Asset, out_dir: Path) -> float:
    """Bounding-box diagonal of the visual mesh [m]; gyration length if it cannot be read."""
    import trimesh

    try:
        mesh = trimesh.load(out_dir / asset.geometry.visual, force="mesh", process=False)
        size = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
        if math.isfinite(size) and size > 0:
            return size
    except Exception:  # fall back below; the loaders report unreadable meshes themselves
        pass
    inertial = asset.theta.inertial()
    return float(math.sqrt(np.trace(inertial.inertia_matrix()) / inertial.mass))


def _compare(asset: Asset, reading: Reading, size_m: float) -> dict[str, float | None]:
    from scipy.spatial.transform import Rotation

    inertial = asset.theta.inertial()
    I0 = inertial.inertia_matrix()
    errors: dict[str, float | None] = {
        "mass_error": abs(reading.mass - inertial.mass) / inertial.mass,
        "com_error": float(np.linalg.norm(reading.com - np.array(inertial.com))) / max(size_m, _COM_FLOOR_M),
        "inertia_error": float(np.linalg.norm(reading.inertia - I0) / np.linalg.norm(I0)),
        "friction_error": None,
        "placement_error": None,
    }
    if reading.friction is not None:
        mu0 = float(asset.theta.friction.value)
        errors["friction_error"] = abs(reading.friction - mu0) / max(abs(mu0), 1e-9)
    if reading.position is not None and reading.quaternion_xyzw is not None:
        p0 = np.array(asset.placement.position)
        q0 = np.array(asset.placement.quaternion_xyzw)
        # atan2-based magnitude: acos(|q . q0|) loses half the digits near identity.
        angle = float((Rotation.from_quat(q0).inv() * Rotation.from_quat(reading.quaternion_xyzw)).magnitude())
        scale = max(float(np.linalg.norm(p0)), size_m)
        errors["placement_error"] = max(float(np.linalg.norm(reading.position - p0)) / scale, angle)
    return errors


def _check(asset: Asset, fmt: str, loader: str, reader: Reader, path: Path, size_m: float, tol: float) -> LoaderCheck:
    # Loaders warn (e.g. Newton on a missing mesh) and carry on; keep what they said with the check.
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            reading = reader(asset, path)
        except Exception as exc:  # any loader failure is a finding, reported per loader
            said = "".join(f"; {w.category.__name__}: {w.message}" for w in caught)
            return LoaderCheck(
                loader=loader, format=fmt, file=str(path), ok=False, error=f"{type(exc).__name__}: {exc}{said}"
            )
    said = tuple(f"{w.category.__name__}: {w.message}" for w in caught)
    errors = _compare(asset, reading, size_m)
    finite = [e for e in errors.values() if e is not None]
    max_error = max(finite) if all(math.isfinite(e) for e in finite) else math.inf
    return LoaderCheck(
        loader=loader,
        format=fmt,
        file=str(path),
        ok=max_error <= tol,
        mass=reading.mass,
        com=tuple(float(v) for v in reading.com),
        inertia=tuple(tuple(float(v) for v in row) for row in reading.inertia),
        friction=reading.friction,
        position=None if reading.position is None else tuple(float(v) for v in reading.position),
        quaternion_xyzw=None if reading.quaternion_xyzw is None else tuple(float(v) for v in reading.quaternion_xyzw),
        max_error=max_error,
        notes=reading.notes + said,
        **errors,
    )


def paths_from(paths: Any, out_dir: Path) -> dict[str, Path]:
    """{"mjcf"|"urdf"|"usd"|"scene": absolute path} from a mapping (asset.json files) or an object with attributes."""
    found: dict[str, Path] = {}
    for key in LOADERS:
        value = paths.get(key) if isinstance(paths, Mapping) else getattr(paths, key, None)
        if value is not None:
            p = Path(value)
            found[key] = p if p.is_absolute() else out_dir / p
    return found


def validate_exports(
    asset: Asset, out_dir: Path, paths: Any, *, tolerance: float = DEFAULT_TOLERANCE, strict: bool = True
) -> ValidationReport:
    """Reload the exported files with every loader and compare with `asset.theta`.

    Args:
        asset: the asset the files were written from.
        out_dir: the output directory (mesh paths and relative `paths` resolve here).
        paths: the written files: a mapping with keys "urdf", "mjcf", "usd" (as
            asset.json → files; other keys ignored) or an object with those
            attributes (e.g. `exporters.ExportPaths`); "scene" too where written. Formats
            left out are not checked.
        tolerance: largest accepted relative error (see the module docstring).
        strict: raise on failure (default); with False, return the failing report.

    Returns:
        The report; `report.ok` is True when every loader agrees within `tolerance`.

    Raises:
        ValidationError: a loader failed to read a file or disagreed; `.report`
            holds the full report.
    """
    out_dir = Path(out_dir)
    files = paths_from(paths, out_dir)
    if not files:
        raise ValidationError(out_dir, f"no exported files to validate (expected keys {tuple(LOADERS)})")
    size_m = reference_size_m(asset, out_dir)
    checks = []
    for fmt, path in files.items():
        if not path.is_file():
            checks.append(LoaderCheck(loader="(file)", format=fmt, file=str(path), ok=False, error="file not found"))
            continue
        for loader, reader in LOADERS[fmt]:
            checks.append(_check(asset, fmt, loader, reader, path, size_m, tolerance))
    inertial = asset.theta.inertial()
    report = ValidationReport(
        ok=all(c.ok for c in checks),
        tolerance=tolerance,
        object_size_m=size_m,
        checks=tuple(checks),
        expected={
            "mass": inertial.mass,
            "com": inertial.com,
            "inertia": inertial.inertia,
            "friction": float(asset.theta.friction.value),
            "position": asset.placement.position,
            "quaternion_xyzw": asset.placement.quaternion_xyzw,
        },
    )
    if strict and not report.ok:
        bad = report.failures()
        lines = [
            f"{c.loader} ({c.format}): {c.error}" if c.error else f"{c.loader} ({c.format}): max relative error "
            f"{c.max_error:.3g} > {tolerance:g} ({_worst(c)})"
            for c in bad
        ]
        raise ValidationError(bad[0].file, "; ".join(lines), report)
    return report


def _worst(check: LoaderCheck) -> str:
    names = ("mass_error", "com_error", "inertia_error", "friction_error", "placement_error")
    values = {n: getattr(check, n) for n in names if getattr(check, n) is not None}
    name = max(values, key=lambda n: values[n])
    return f"{name.removesuffix('_error')} {values[name]:.3g}"
