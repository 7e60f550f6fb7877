"""diagnose: locate where simulation and recordings disagree, name the missing physics, model it, choose on held-out data."""

from .effects import CANDIDATES, EFFECT_NAMES, NONUNIFORM_DENSITY, Candidate, main_magnitude
from .residuals import ResidualAnalysis, analyse_residuals, describe
from .screening import Screening, screen
from .select import DiagnoseConfig, Diagnosis, diagnose_held

__all__ = [
    "CANDIDATES", "Candidate", "DiagnoseConfig", "Diagnosis", "EFFECT_NAMES", "NONUNIFORM_DENSITY",
    "ResidualAnalysis", "Screening", "analyse_residuals", "describe", "diagnose_held", "main_magnitude", "screen",
]
