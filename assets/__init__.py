"""The twin data model: depends on nothing else of ours."""

from .io import SCHEMA, AssetError, asset_from_json, asset_to_json, read_asset, write_asset
from .model import (
    COM,
    FLAT_INERTIAL,
    KINDS,
    MASS,
    MOMENTS,
    PRODUCTS,
    Asset,
    Effect,
    Estimate,
    Fit,
    FitMetrics,
    Geometry,
    Inertial,
    Joint,
    Material,
    Pose,
    Theta,
    flat_inertial,
    symmetric_from_flat,
)

__all__ = [
    "COM", "FLAT_INERTIAL", "KINDS", "MASS", "MOMENTS", "PRODUCTS", "SCHEMA", "Asset", "AssetError", "Effect", "Estimate", "Fit", "FitMetrics", "Geometry", "Inertial",
    "Joint", "Material", "Pose", "Theta", "asset_from_json", "asset_to_json", "read_asset", "write_asset",
    "flat_inertial", "symmetric_from_flat",
]
