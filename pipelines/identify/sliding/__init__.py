"""Pushed objects: surface friction (with mass and yaw inertia where the data determine them).

An object pushed across a support surface is simulated in Newton with
SemiImplicit and its collision pipeline, gradients from a Warp tape: one world
per shooting window, each started from the measured planar state (x, y, yaw and
their rates), driven by the measured pusher force applied at the measured
contact point, compared with the measured motion.

The support face is sampled by a grid of point contacts (small spheres, uniform
pressure). A box's own collision shape touches a plane at its four corners,
which puts all the friction at the largest radius and roughly doubles the
friction torque that resists turning; a 4 x 4 grid gets the mean lever arm of a
uniformly loaded square within 2 %.

Penalty friction in Newton is viscous below a slip speed (kf |v_t| < mu f_n)
and Coulomb above; its gradient w.r.t. mu is zero in the viscous branch, so
only windows in which the object slides are fitted (newton.md, "sticking").
A slow, quasi-static push balances on a knife edge when driven by the measured
force (a little below mu m g the object sticks, a little above it runs away):
a fit whose simulation sticks in every window has only bounded mu
(`sliding_windows`), and the wrench balance of the windows in which the object
slides throughout measures it without a simulation (`wrench_balance_friction`).
A window whose turn its pushing moment cannot give (friction would have to drive
it: `turn_check`) is a mismatch no coefficient explains, and the I_zz a fit needs
to follow it is not the body's.

Parameters are theta = (mu, m [kg], I_zz [kg m^2]). Pushes that are nearly
quasi-static determine mu * m (force balance) better than either alone; a
log-normal prior on m and I_zz closes the problem, and each parameter whose
curvature from the data is below the prior's is reported as taken from the prior.
"""

from .balance import (
    TurnCheck,
    WrenchBalance,
    measured_friction,
    quasi_static_friction,
    steady_windows,
    turn_check,
    wrench_balance_error,
    wrench_balance_friction,
)
from .body import SUPPORTS, PlanarBody, SlidingConfig
from .fit import SlidingFit, friction_start, identify_sliding
from .pushed import PushedIdentification, SupportChoice, choose_support, identify_pushed
from .rollout import EFFECT_SLOTS, SlidingRollout, replay_errors, sliding_windows
from .windows import ForceBias, PushWindows, concat_push_windows, estimate_force_bias, push_windows

__all__ = [
    "EFFECT_SLOTS",
    "SUPPORTS",
    "ForceBias",
    "PlanarBody",
    "PushWindows",
    "SlidingConfig",
    "SlidingFit",
    "SlidingRollout",
    "SupportChoice",
    "choose_support",
    "PushedIdentification",
    "concat_push_windows",
    "estimate_force_bias",
    "friction_start",
    "identify_pushed",
    "identify_sliding",
    "measured_friction",
    "replay_errors",
    "push_windows",
    "sliding_windows",
    "quasi_static_friction",
    "steady_windows",
    "turn_check",
    "TurnCheck",
    "wrench_balance_error",
    "wrench_balance_friction",
    "WrenchBalance",
]
