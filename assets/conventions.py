"""World-frame conventions shared by every stage.

The world frame is right-handed with z up; gravity points along -z. All
quantities are SI (metres, kilograms, seconds, newtons, radians).
"""

from __future__ import annotations

import numpy as np

GRAVITY_MAGNITUDE_M_S2 = 9.81
"""Standard gravity [m/s^2], the magnitude of `GRAVITY_M_S2`."""

GRAVITY_M_S2 = np.array([0.0, 0.0, -GRAVITY_MAGNITUDE_M_S2])
"""Gravitational acceleration in the world frame [m/s^2] (z up, so it points along -z)."""

__all__ = ["GRAVITY_MAGNITUDE_M_S2", "GRAVITY_M_S2"]
