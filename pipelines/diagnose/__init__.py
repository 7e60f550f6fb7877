"""diagnose: locate where simulation and recordings disagree, name the missing physics, model it, choose on held-out data."""

from .effects import CANDIDATES, EFFECT_NAMES, NONUNIFORM_DENSITY, Candidate, main_magnitude
from .joint import JOINT_CANDIDATES, diagnose_jointed, joint_effect_params, replay_fit
from .pushed import PUSHED_CANDIDATES, diagnose_pushed
from .residuals import ResidualAnalysis, analyse_residuals, describe
from .screening import Screening, screen
from .select import DiagnoseConfig, Diagnosis, diagnose_held, replay_held

__all__ = [
    "CANDIDATES", "Candidate", "DiagnoseConfig", "Diagnosis", "EFFECT_NAMES", "JOINT_CANDIDATES",
    "NONUNIFORM_DENSITY", "PUSHED_CANDIDATES", "ResidualAnalysis", "Screening", "analyse_residuals", "describe",
    "diagnose_held", "diagnose_jointed", "diagnose_pushed", "joint_effect_params", "main_magnitude",
    "replay_fit", "replay_held", "screen",
]
