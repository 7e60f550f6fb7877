"""Priors from geometry x material: uniform-density theta0 and the bounds C."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from assets import Inertial
from assets.materials import MaterialRange


@dataclass(frozen=True)
class Prior:
    """theta0 and box bounds C in the object frame, with what they came from.

    lower/upper: (mass [kg], com xyz [m], Ixx Iyy Izz [kg m^2]). `uniform` is the
    uniform-density body at the central density, kept for later diagnosis.
    """

    inertial: Inertial
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    material: MaterialRange
    volume_m3: float
    uniform: Inertial

    def provenance(self) -> dict:
        return {
            "material": self.material.name,
            "density_kg_m3": [self.material.density_low, self.material.density, self.material.density_high],
            "source": self.material.source,
            "volume_m3": self.volume_m3,
            "mass_kg": self.inertial.mass,
            "lower": list(self.lower),
            "upper": list(self.upper),
        }


def uniform_density_prior(mesh_object, material: MaterialRange, inertia_spread: tuple[float, float] = (0.3, 2.0)) -> Prior:
    """theta0 at the material's central density; C from its density range.

    mesh_object: watertight trimesh in the object frame (metres). The inertia
    bounds widen the uniform body's by `inertia_spread` for non-uniform fill
    (shells and heavy inserts move mass outwards or inwards).
    """
    if not mesh_object.is_volume:
        raise ValueError("prior needs a watertight mesh with consistent normals")
    volume = float(mesh_object.volume)
    mesh_object = mesh_object.copy()
    mesh_object.density = 1.0
    unit_inertia = np.asarray(mesh_object.moment_inertia)  # about the centroid, per unit density
    com = np.asarray(mesh_object.center_mass)
    uniform = Inertial(material.density * volume, com, material.density * unit_inertia)
    half = 0.5 * (mesh_object.bounds[1] - mesh_object.bounds[0])
    diag = np.diag(unit_inertia)
    lower = (material.density_low * volume, *(com - half), *(material.density_low * diag * inertia_spread[0]))
    upper = (material.density_high * volume, *(com + half), *(material.density_high * diag * inertia_spread[1]))
    return Prior(uniform, tuple(map(float, lower)), tuple(map(float, upper)), material, volume, uniform)
