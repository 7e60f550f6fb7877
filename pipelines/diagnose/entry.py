"""`diagnose`: the diagnosis of a body of any kind, dispatched once on its subject's type."""

from __future__ import annotations

from dataclasses import replace

from pipelines.identify import HeldBody, JointedPart, PushedBody, Subject

from .config import DiagnoseConfig
from .joint import diagnose_jointed
from .pushed import diagnose_pushed
from .select import Diagnosis, diagnose_held


def diagnose(subject: Subject, trials: list, holdout=None, config: DiagnoseConfig = DiagnoseConfig()):
    """Diagnose `subject` from `trials` (Recordings); `holdout` (a Recording or None) chooses and validates.

    Returns (Diagnosis, refit): the refit is the body identified again with the chosen effects (a held body's
    PosteriorResult, a pushed body's SlidingFit, a part's JointedIdentification), or None where no effect
    needed one.
    """
    match subject:
        case HeldBody():
            diagnosis: Diagnosis = diagnose_held(trials, holdout, subject.X_tracked_body, subject.uniform,
                                                 replace(config, window_s=subject.window_s))
            return diagnosis, diagnosis.posterior
        case PushedBody():
            return diagnose_pushed(trials, [holdout] if holdout else [], subject.body, subject.mu_prior,
                                   subject.config, config)
        case JointedPart():
            return diagnose_jointed(trials, holdout, subject.joint, subject.placement, subject.prior, subject.config,
                                    config)
    raise TypeError(f"diagnose: expected a HeldBody, PushedBody or JointedPart, got {type(subject).__name__}")
