"""identify: a body's physics from recordings, by least squares and differentiable simulation in Newton.

One module per kind, and this face is what other stages use (the diagnosis refits through it):

- held (free) bodies: `identify_held` keeps the posterior of least squares and the geometry prior, or the
  Newton fit where it predicts the held-out recording better (`free_body`, `least_squares`, `posterior`);
- pushed (sliding) objects: `identify_pushed` chooses the support and fits friction (`sliding`);
- jointed parts: `identify_jointed` on the joint `detect_kind` finds (`jointed`, `kind`).

Each kind's body as its model sees it is a subject (`HeldBody`, `PushedBody`, `JointedPart`): the diagnosis
takes one (`pipelines.diagnose.diagnose`), and a build records it for a later `twin diagnose`.
"""

from .free_body import Identification, IdentifyConfig, InertialBounds, identify_free_body
from .held import HeldIdentification, identify_held, tracked_to_object, with_weighed_mass
from .inertia import nearest_physical_inertia, theta_from_physical
from .jointed import (
    JOINT_EFFECT_PARAMS, STRIBECK_SPEEDS, JointedConfig, JointedIdentification, equation_of_motion_rows,
    identify_jointed, joint_body, joint_effect_columns, joint_windows, moving_mask, q_and_position_rmse,
    replay_jointed,
)
from .kernels import EFFECT_SIZE
from .kind import JointFit, KindDetection, detect_kind, joint_coordinates
from .least_squares import (
    LeastSquaresResult, NewtonEulerRows, identify_least_squares, newton_euler_rows, object_frame_from_pi,
)
from .noise import estimate_noise_levels, recording_noise_levels, renoised
from .posterior import DataTerm, PosteriorConfig, PosteriorResult, identify_posterior
from .rollout import FreeBodyRollout
from .sliding import (
    EFFECT_SLOTS, SUPPORTS, PlanarBody, PushWindows, SlidingConfig, SlidingFit, SlidingRollout, concat_push_windows,
    estimate_force_bias, identify_pushed, identify_sliding, measured_friction, push_windows, turn_check,
)
from .subjects import HeldBody, JointedPart, PushedBody, Subject, subject_from_json
from .windows import ShootingWindows, concat_windows, make_windows, predicts_better

__all__ = [
    "DataTerm", "EFFECT_SIZE", "EFFECT_SLOTS", "JOINT_EFFECT_PARAMS", "STRIBECK_SPEEDS", "SUPPORTS", "FreeBodyRollout",
    "HeldBody", "HeldIdentification", "Identification", "IdentifyConfig", "InertialBounds", "JointFit",
    "JointedConfig", "JointedIdentification", "JointedPart", "KindDetection", "LeastSquaresResult", "NewtonEulerRows",
    "PlanarBody", "PosteriorConfig", "PosteriorResult", "PushWindows", "PushedBody", "ShootingWindows",
    "SlidingConfig", "SlidingFit", "SlidingRollout", "Subject", "concat_push_windows", "concat_windows",
    "detect_kind", "equation_of_motion_rows", "estimate_force_bias", "estimate_noise_levels", "identify_free_body",
    "identify_held", "identify_jointed", "identify_least_squares", "identify_posterior", "identify_pushed",
    "identify_sliding", "joint_body", "joint_coordinates", "joint_effect_columns", "joint_windows", "make_windows",
    "measured_friction", "moving_mask", "nearest_physical_inertia", "newton_euler_rows", "object_frame_from_pi",
    "predicts_better", "push_windows", "q_and_position_rmse", "recording_noise_levels", "renoised", "replay_jointed",
    "subject_from_json", "theta_from_physical", "tracked_to_object", "turn_check", "with_weighed_mass",
]
