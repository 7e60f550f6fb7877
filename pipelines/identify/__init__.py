"""identify: inertial parameters of a held body from recordings, by differentiable simulation in Newton."""

from .free_body import Identification, IdentifyConfig, InertialBounds, identify_free_body
from .held import HeldIdentification, identify_held, tracked_to_object, with_weighed_mass
from .least_squares import LeastSquaresResult, identify_least_squares
from .posterior import PosteriorConfig, PosteriorResult, identify_posterior
from .windows import ShootingWindows, concat_windows, make_windows

__all__ = [
    "HeldIdentification", "Identification", "IdentifyConfig", "InertialBounds", "LeastSquaresResult",
    "PosteriorConfig", "PosteriorResult", "identify_posterior",
    "ShootingWindows", "concat_windows", "identify_free_body", "identify_held", "identify_least_squares",
    "make_windows", "tracked_to_object", "with_weighed_mass",
]
