"""The pushed body, the sliding fit's settings and the support face's point contacts."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


_GRID = 4  # contacts per side of the support face
SUPPORTS = ("uniform", "corners")
"""Support-face load models of `SlidingConfig.support`."""


@dataclass(frozen=True)
class PlanarBody:
    """The pushed object as the simulation sees it (object frame at the COM, z up).

    half_extents_m: half sizes of its bounding box (x, y, z) [m]; the support
        face is the box's bottom face.
    mass_kg, izz_kgm2: prior values (inertia about the vertical axis through the COM).
    mass_rel_std, izz_rel_std: prior spread, as the std of the log.
    """

    half_extents_m: tuple[float, float, float]
    mass_kg: float
    izz_kgm2: float
    mass_rel_std: float = 0.3
    izz_rel_std: float = 0.3

    def __post_init__(self):
        h = np.asarray(self.half_extents_m, dtype=float)
        if h.shape != (3,) or not np.all(h > 0):
            raise ValueError(f"PlanarBody.half_extents_m: expected three positive sizes [m], got {self.half_extents_m}")
        for name in ("mass_kg", "izz_kgm2", "mass_rel_std", "izz_rel_std"):
            if not getattr(self, name) > 0:
                raise ValueError(f"PlanarBody.{name}: expected > 0, got {getattr(self, name)!r}")


@dataclass(frozen=True)
class SlidingConfig:
    """Settings of the sliding identification (recorded in asset.json provenance).

    window_s: shooting-window length [s]. dt_s: simulation step [s].
    moving_speed_m_s: a window is fitted only if the object's median speed in it
        exceeds this (sliding, not sticking) [m/s].
    contact_margin_m: the pusher counts as touching when the contact point lies
        within the support face's circumradius plus this [m].
    yaw_length_m: heading errors are weighted as arc lengths at this radius
        (default: the face's half diagonal) [m].
    mu_bounds: admissible friction coefficients.
    smoothing_hz: zero-phase low-pass of the poses when finding the first and last motion (bias).
    twist_half_width: samples each side of a window's start in the quadratic fit
        of its start velocity.
    max_iterations: L-BFGS-B iterations.
    """

    window_s: float = 0.3
    dt_s: float = 2e-3
    moving_speed_m_s: float = 0.01
    contact_margin_m: float = 0.02
    yaw_length_m: float | None = None
    mu_bounds: tuple[float, float] = (0.02, 2.0)
    smoothing_hz: float = 10.0
    sample_period_s: float = 0.01
    """Pose samples are resampled to this period [s], so windows of any recording share one batch."""
    pusher_clear_m: float = 0.003
    """The pusher is away from the object (a zero of the force offset) once its contact point is this
    much farther from the object's origin, horizontally, than when the object first moved [m] ..."""
    lift_m: float = 0.01
    """... or this far above its height while pushing [m] (a pusher lifted off may stay above the object)."""
    preload_fraction: float = 0.05
    """A pusher resting on the object before the push preloads it when the force then exceeds the
    pusher-away zero after the push, along the push, by this fraction of the median pushing force."""
    jump_m: float = 0.005
    """Tracker samples further than this from a running median are dropped [m]."""
    twist_half_width: int = 3
    max_iterations: int = 30
    contact_sink_m: float = 3e-4
    """Static sink of the face under the object's weight [m]: sets the normal stiffness m g / sink,
    so the contact's frequency sqrt(g / sink) is the same for any mass."""
    contact_damping_ratio: float = 0.7
    max_delay_s: float = 0.05
    """The force is kept this far beyond each window's ends: the range a time delay is fitted over [s]."""
    support: str = "uniform"
    """Where the support face carries the weight: "uniform" (a grid over the face: a flat face on a flat
    table, the default) or "corners" (its four corners, as MuJoCo's box-plane and mesh-plane contacts put
    them: about twice the friction moment against turning; docs/pushes.md)."""
    fit_mass: bool = False
    """Fit the mass too. Pushes determine mu m through the force balance; the split rests on the
    accelerations, which 5 ms of force-to-pose timing error moves by about 10 % (twin bench push),
    so by default the mass keeps its prior (marked so) and mu is measured given it."""

    def __post_init__(self):
        if self.support not in SUPPORTS:
            raise ValueError(f"SlidingConfig.support: expected one of {SUPPORTS}, got {self.support!r}")


def support_points(body: PlanarBody, config: SlidingConfig | None = None) -> np.ndarray:
    """The support face's point contacts, object frame x, y [m]: the cell centres of a _GRID x _GRID grid
    (support "uniform"), or the face's four corners ("corners")."""
    hx, hy, _ = body.half_extents_m
    if config is not None and config.support == "corners":
        return np.array([(sx * hx, sy * hy) for sx in (-1.0, 1.0) for sy in (-1.0, 1.0)])
    cells = (np.arange(_GRID) + 0.5) / _GRID * 2.0 - 1.0
    return np.array([(gx * hx, gy * hy) for gx in cells for gy in cells])
