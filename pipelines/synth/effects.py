"""Concealed effects sized from the sensor's noise: physics a synthetic recording carries and the model lacks.

The size is given as a multiple ("ratio") of the per-sample sensor noise: force or torque for bias, damping
and drag (damping b = ratio sigma / SPEED_M_S, drag c = ratio sigma / SPEED_M_S^2, angular damping through
TURN_RAD_S); 2 ms per unit for delay; a millimetre per unit for the COM shift. On a joint the unit is the
per-sample joint effort noise sigma (the force noise, times the handle's lever on a hinge): damping
b = ratio sigma / v, v = 0.8 travel/s a typical joint speed; spring k = ratio sigma / (travel / 4) about a
rest position inside the travel; Stribeck excess f_s - f_c = 5 ratio sigma (it acts only near reversals),
v_s 5-20 % of v.
"""

from __future__ import annotations

import numpy as np

from .held import ConcealedEffect

EFFECTS = ("sensor_bias", "time_delay", "viscous_damping", "quadratic_drag", "nonuniform_density")
"""Effects of a held body."""
JOINT_EFFECTS = ("viscous_damping", "spring", "stribeck_friction")
"""Effects on a part's joint."""
SPEED_M_S = 0.15
"""Typical speed of the COM in these motions [m/s], to turn a force ratio into damping and drag."""
TURN_RAD_S = 2.0
"""Typical angular speed [rad/s]."""


def concealed_effect(name: str, ratio: float, rng: np.random.Generator, noise) -> ConcealedEffect:
    """A ConcealedEffect of `name` whose size is `ratio` times the sensor's noise (see module docstring)."""
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    other = rng.normal(size=3)
    other /= np.linalg.norm(other)
    if name == "sensor_bias":
        return ConcealedEffect(name, {"force": (ratio * noise.force_sigma_n * direction).tolist(),
                                      "torque": (ratio * noise.torque_sigma_nm * other).tolist()})
    if name == "time_delay":
        return ConcealedEffect(name, {"seconds": float(rng.choice([-1, 1]) * ratio * 2e-3)})
    if name == "viscous_damping":
        return ConcealedEffect(name, {"b": ratio * noise.force_sigma_n / SPEED_M_S,
                                      "b_angular": ratio * noise.torque_sigma_nm / TURN_RAD_S})
    if name == "quadratic_drag":
        return ConcealedEffect(name, {"c": ratio * noise.force_sigma_n / SPEED_M_S**2})
    if name == "nonuniform_density":
        return ConcealedEffect(name, {"com_shift": (ratio * 1e-3 * direction).tolist()})
    raise ValueError(f"{name}: not an effect of a held body ({', '.join(EFFECTS)}); joint effects need --object")


def joint_effort_noise(obj, noise) -> float:
    """Per-sample noise of the joint effort [N or N m]: the force noise, times the handle's lever on a hinge."""
    if obj.joint_type == "prismatic":
        return noise.force_sigma_n
    handle = np.asarray(obj.position_m) + np.asarray(obj.handle_m) - np.asarray(obj.origin_m)
    return noise.force_sigma_n * float(np.linalg.norm(np.cross(obj.axis, handle)))


def concealed_joint_effect(name: str, ratio: float, rng: np.random.Generator, obj, noise) -> ConcealedEffect:
    """A ConcealedEffect of `name` on `obj`'s joint whose size is `ratio` times its effort noise (see module
    docstring)."""
    sigma = joint_effort_noise(obj, noise)
    travel = obj.travel[1] - obj.travel[0]
    speed = 0.8 * travel
    if name == "viscous_damping":
        return ConcealedEffect(name, {"b": ratio * sigma / speed})
    if name == "spring":
        return ConcealedEffect(name, {"k": ratio * sigma / (travel / 4), "q0": float(rng.uniform(*obj.travel))})
    if name == "stribeck_friction":
        return ConcealedEffect(name, {"f_s": obj.friction + 5 * ratio * sigma, "f_c": obj.friction,
                                      "v_s": float(speed * np.exp(rng.uniform(np.log(0.05), np.log(0.2))))})
    raise ValueError(f"{name}: not a joint effect ({', '.join(JOINT_EFFECTS)})")
