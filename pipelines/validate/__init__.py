"""Reload the exported URDF, MJCF and USD files in real loaders and check them.

Each file is read by two loaders (MJCF: MuJoCo and Newton; URDF: yourdfpy and
Newton; USD: usd-core's UsdPhysics and Newton); a pushed object's scene.xml by
MuJoCo, which also lets it rest on its support plane. For every loader the mass
[kg], COM [m] and full inertia tensor about the COM [kg m^2], in the object
frame, are compared with `asset.theta`; so are surface friction and the
placement where the format and the loader carry them. Any disagreement above
the tolerance, or any file a loader cannot read, raises `ValidationError`.
Bodies, links, joints and prims are looked up by the names the writers gave
them, derived from `asset.name` by `exporters.names`.

`replay_held_mujoco`, `replay_pushed_mujoco` and `replay_jointed_mujoco` run the
exported files in MuJoCo on a held-out recording, in the windows the build
scores Newton's fit on, so the two simulators' errors stand side by side.

Relative errors:
    mass       |m - m0| / m0
    com        |c - c0| / max(L, 1e-9 m), L the object size (the visual mesh's
               bounding-box diagonal; sqrt(tr I / m) if that mesh is unreadable)
    inertia    ||I - I0||_F / ||I0||_F
    friction   |mu - mu0| / max(|mu0|, 1e-9)
    placement  max(|p - p0| / max(|p0|, L), rotation angle [rad]); Newton keeps
               poses in float32, hence |p0| in the scale

Modules: `loaders` (one reader per loader and format), `exports` (`validate_exports`),
`jointed` (`validate_jointed_exports`), `replay` (the MuJoCo replays) and `report`.
"""

from .exports import validate_exports
from .jointed import validate_jointed_exports
from .loaders import LOADERS
from .replay import (
    pushed_effects, replay_held_mujoco, replay_jointed_mujoco, replay_pushed_model, replay_pushed_mujoco,
)
from .report import DEFAULT_TOLERANCE, LoaderCheck, ValidationError, ValidationReport

__all__ = ["DEFAULT_TOLERANCE", "LOADERS", "LoaderCheck", "ValidationError", "ValidationReport", "pushed_effects",
           "replay_held_mujoco", "replay_jointed_mujoco", "replay_pushed_model", "replay_pushed_mujoco",
           "validate_exports", "validate_jointed_exports"]
