"""diagnose: locate where simulation and recordings disagree, name the missing physics, model it, choose on held-out data.

The settings (`DiagnoseConfig`) load at once; the rest loads on first use, because it brings Warp and Newton
with it and the command line reads the settings to build its options.
"""

from importlib import import_module

from .config import DiagnoseConfig

_WHERE = {
    "CANDIDATES": "effects", "EFFECT_NAMES": "effects", "NONUNIFORM_DENSITY": "effects", "Candidate": "effects",
    "main_magnitude": "effects", "without_recording_effects": "effects",
    "JOINT_CANDIDATES": "joint", "diagnose_jointed": "joint", "joint_effect_params": "joint", "replay_fit": "joint",
    "PUSHED_CANDIDATES": "pushed", "diagnose_pushed": "pushed",
    "ResidualAnalysis": "residuals", "analyse_residuals": "residuals", "describe": "residuals",
    "Screening": "screening", "screen": "screening",
    "Diagnosis": "select", "diagnose_held": "select", "replay_held": "select",
    "diagnose": "entry",
}

__all__ = ["DiagnoseConfig", *_WHERE]


def __getattr__(name: str):
    if name not in _WHERE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(f".{_WHERE[name]}", __name__), name)
    globals()[name] = value
    return value
