"""What validation reports: one loader's check, the report of all of them, and the error."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np


DEFAULT_TOLERANCE = 1e-6
"""Largest relative error accepted (float32 storage in USD and Newton is ~6e-8)."""


class ValidationError(Exception):
    """An exported file that a loader cannot read, or reads with other values.

    Attributes:
        path: the offending file.
        message: what went wrong.
        report: the full `ValidationReport` when one was made, else None.
    """

    def __init__(self, path: Path | str, message: str, report: "ValidationReport | None" = None):
        self.path = Path(path)
        self.message = message
        self.report = report
        super().__init__(f"{self.path}: {message}")


@dataclass(frozen=True)
class LoaderCheck:
    """What one loader read from one file, in the object frame, and how far off it is.

    mass [kg]; com [m]; inertia [kg m^2] about the COM, object-frame axes;
    friction unitless (None where the format or loader does not carry it);
    placement position [m] and quaternion (x, y, z, w) of the body in world
    (None where not carried, e.g. URDF). `*_error` are relative errors (see
    the module docstring); `error` holds the load failure, if any.
    """

    loader: str
    format: str
    file: str
    ok: bool
    mass: float | None = None
    com: tuple[float, float, float] | None = None
    inertia: tuple[tuple[float, float, float], ...] | None = None
    friction: float | None = None
    position: tuple[float, float, float] | None = None
    quaternion_xyzw: tuple[float, float, float, float] | None = None
    mass_error: float | None = None
    com_error: float | None = None
    inertia_error: float | None = None
    friction_error: float | None = None
    placement_error: float | None = None
    max_error: float | None = None
    notes: tuple[str, ...] = ()
    error: str | None = None

    def to_json(self) -> dict[str, Any]:
        return _jsonable(asdict(self))


@dataclass(frozen=True)
class ValidationReport:
    """One `LoaderCheck` per loader and the overall verdict."""

    ok: bool
    tolerance: float
    object_size_m: float
    checks: tuple[LoaderCheck, ...]
    expected: dict = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """A JSON-serialisable dict (for asset.json provenance and the HTML report)."""
        return {
            "ok": self.ok,
            "tolerance": self.tolerance,
            "object_size_m": self.object_size_m,
            "expected": _jsonable(self.expected),
            "checks": [c.to_json() for c in self.checks],
        }

    def failures(self) -> tuple[LoaderCheck, ...]:
        return tuple(c for c in self.checks if not c.ok)


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple, np.ndarray)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(x) else None  # NaN/inf are not JSON
    return x
