"""The twin data model: depends on nothing else of ours."""

from .io import SCHEMA, AssetError, asset_from_json, asset_to_json, read_asset, write_asset
from .model import (
    KINDS,
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
)

__all__ = [
    "KINDS", "SCHEMA", "Asset", "AssetError", "Effect", "Estimate", "Fit", "FitMetrics", "Geometry", "Inertial",
    "Joint", "Material", "Pose", "Theta", "asset_from_json", "asset_to_json", "read_asset", "write_asset",
]
