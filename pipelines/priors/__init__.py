"""Priors: theta0 and bounds C from geometry x material, fused with a VLM's guess.

geometry: mass properties of a mesh as a solid, a shell or a 3D print; fusion:
the distributions and their product; vlm: the chat-completions client.
"""

from .fusion import PriorConfig, estimate_prior
from .geometry import (
    BodyMoments,
    Prior,
    infill_moments,
    inner_moments,
    moments_from_mesh,
    part_pseudo_inertias,
    shell_moments,
    solid_moments,
    uniform_density_prior,
)
from .vlm import ObjectFacts, VlmConfig, VlmGuess, ask_vlm, describe_object, parse_answer, scan_image

__all__ = [
    "BodyMoments", "ObjectFacts", "Prior", "PriorConfig", "VlmConfig", "VlmGuess", "ask_vlm", "describe_object",
    "estimate_prior", "infill_moments", "inner_moments", "moments_from_mesh", "parse_answer", "part_pseudo_inertias",
    "scan_image", "shell_moments", "solid_moments", "uniform_density_prior",
]
