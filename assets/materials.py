"""The material library: density and friction ranges with their sources (materials.json).

Every range is a triple (central, low, high): low..high is a credible range of
about 95 %, and the priors read it as a log-normal whose median is the central
value (`pipelines.priors`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Literal

LIBRARY_PATH = Path(__file__).with_name("materials.json")
UNKNOWN = "unknown"

Structure = Literal["solid", "printed", "shell"]
STRUCTURES: tuple[str, ...] = ("solid", "printed", "shell")


@dataclass(frozen=True)
class MaterialRange:
    """A material's density [kg/m^3] and Coulomb friction (unitless): central value and credible range.

    density*: bulk density of an object of this material (mass / enclosed volume).
    friction*: static coefficient against common surfaces; friction_kinetic*: the sliding one.
    structure: how the geometry prior fills the mesh: "solid"; "printed" (walls plus a
      partial infill of `solid_density`); "shell" (hollow, walls of `wall_m` of `solid_density`).
    solid_density: (central, low, high) [kg/m^3] of the wall material, or None (= density).
    wall_m: (central, low, high) wall thickness [m] of a shell, or None.
    """

    name: str
    density: float
    density_low: float
    density_high: float
    friction: float
    friction_low: float
    friction_high: float
    source: str
    friction_kinetic: float | None = None
    friction_kinetic_low: float | None = None
    friction_kinetic_high: float | None = None
    structure: Structure = "solid"
    solid_density: tuple[float, float, float] | None = None
    wall_m: tuple[float, float, float] | None = None
    category: str = ""

    def wall_density(self) -> tuple[float, float, float]:
        """(central, low, high) [kg/m^3] of the material the walls (or the whole solid) are made of."""
        if self.solid_density is not None:
            return self.solid_density
        return (self.density, self.density_low, self.density_high)

    def kinetic(self) -> tuple[float, float, float]:
        """(central, low, high) kinetic friction; 0.8 x the static range where the library gives none."""
        if self.friction_kinetic is None:
            return (0.8 * self.friction, 0.8 * self.friction_low, 0.8 * self.friction_high)
        return (self.friction_kinetic, self.friction_kinetic_low, self.friction_kinetic_high)


@cache
def _library() -> dict:
    try:
        lib = json.loads(LIBRARY_PATH.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise ValueError(f"{LIBRARY_PATH}: cannot read the material library ({exc})") from exc
    for key, entry in {**lib["materials"], UNKNOWN: lib["unknown"]}.items():
        _check_entry(key, entry)
    return lib


def _check_entry(key: str, entry: dict) -> None:
    """ValueError naming the file, entry and field when a triple is not (central, low, high) with low <= central <= high."""
    for field in ("density", "friction", "friction_kinetic", "solid_density", "wall_m"):
        if field not in entry:
            if field in ("density", "friction"):
                raise ValueError(f"{LIBRARY_PATH}: material {key!r} has no {field!r}")
            continue
        v = entry[field]
        if not (isinstance(v, list) and len(v) == 3 and 0 < v[1] <= v[0] <= v[2]):
            raise ValueError(f"{LIBRARY_PATH}: material {key!r} field {field!r}: expected [central, low, high] "
                             f"with 0 < low <= central <= high, got {v!r}")
    structure = entry.get("structure", "solid")
    if structure not in STRUCTURES:
        raise ValueError(f"{LIBRARY_PATH}: material {key!r}: structure {structure!r} is not one of {STRUCTURES}")
    if structure == "shell" and "wall_m" not in entry:
        raise ValueError(f"{LIBRARY_PATH}: material {key!r}: a shell needs 'wall_m'")
    if not entry.get("source"):
        raise ValueError(f"{LIBRARY_PATH}: material {key!r} names no source")


def material_names() -> tuple[str, ...]:
    return tuple(sorted(_library()["materials"]))


def _normalise(name: str) -> str:
    return name.strip().lower().replace(" ", "_").replace("-", "_")


def find_material(name: str | None) -> MaterialRange | None:
    """The named material (aliases such as 'PLA' or 'aluminum' accepted), or None when the library lacks it."""
    if name is None:
        return None
    lib = _library()
    key = _normalise(name)
    if key == UNKNOWN:
        return material_range(None)
    key = lib.get("aliases", {}).get(key, key)
    if key not in lib["materials"]:
        return None
    return _from_entry(key, lib["materials"][key])


def material_range(name: str | None) -> MaterialRange:
    """The named material, or the wide `unknown` range for None; ValueError names the choices."""
    lib = _library()
    if name is None or name == UNKNOWN:
        return _from_entry(UNKNOWN, lib["unknown"])
    found = find_material(name)
    if found is None:
        raise ValueError(f"unknown material {name!r}; choose one of {', '.join(material_names())}")
    return found


def _from_entry(name: str, entry: dict) -> MaterialRange:
    d, f = entry["density"], entry["friction"]
    fk = entry.get("friction_kinetic", [None, None, None])
    triple = lambda k: tuple(float(x) for x in entry[k]) if k in entry else None  # noqa: E731
    return MaterialRange(
        name, d[0], d[1], d[2], f[0], f[1], f[2], entry["source"],
        friction_kinetic=fk[0], friction_kinetic_low=fk[1], friction_kinetic_high=fk[2],
        structure=entry.get("structure", "solid"), solid_density=triple("solid_density"), wall_m=triple("wall_m"),
        category=entry.get("category", ""),
    )
