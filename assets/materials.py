"""The material library: density and friction ranges with their sources (materials.json)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import cache
from pathlib import Path

LIBRARY_PATH = Path(__file__).with_name("materials.json")
UNKNOWN = "unknown"


@dataclass(frozen=True)
class MaterialRange:
    """A material's density [kg/m^3] and Coulomb friction (unitless): central value and credible range."""

    name: str
    density: float
    density_low: float
    density_high: float
    friction: float
    friction_low: float
    friction_high: float
    source: str


@cache
def _library() -> dict:
    return json.loads(LIBRARY_PATH.read_text())


def material_names() -> tuple[str, ...]:
    return tuple(sorted(_library()["materials"]))


def material_range(name: str | None) -> MaterialRange:
    """The named material, or the wide `unknown` range for None; ValueError names the choices."""
    lib = _library()
    if name is None or name == UNKNOWN:
        entry, name = lib["unknown"], UNKNOWN
    else:
        key = name.strip().lower().replace(" ", "_").replace("-", "_")
        if key not in lib["materials"]:
            raise ValueError(f"unknown material {name!r}; choose one of {', '.join(material_names())}")
        entry, name = lib["materials"][key], key
    d, f = entry["density"], entry["friction"]
    return MaterialRange(name, d[0], d[1], d[2], f[0], f[1], f[2], entry["source"])
