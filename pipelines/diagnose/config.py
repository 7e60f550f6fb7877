"""How the diagnosis screens, refits and chooses: its settings, light to import (the command line reads them)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class DiagnoseConfig:
    """How the diagnosis screens, refits and chooses."""

    bootstraps: int = 40
    """Block-bootstrap resamples of the screening."""
    inclusion_threshold: float = 0.5
    """Candidates screened in at least this often are refitted."""
    leading: int = 3
    """At most this many leading candidates (and their pairs) are refitted."""
    folds: int = 3
    """Time blocks of the cross-validation used when there is no held-out recording."""
    com_sigma: float = 5.0
    """A COM shift must be this many standard deviations (Mahalanobis) from the prior's (a push's contact offset, which
    moves the force against the COM as a COM shift would, from zero) ..."""
    com_floor_m: float = 1e-3
    """... and at least this far [m], to be reported as nonuniform_density."""
    mesh_com_fraction: float = 0.01
    """Without a measured one, the standard deviation per axis of the uniform-density COM that the reconstructed
    mesh gives, as a fraction of the body's radius of gyration: a scanned mesh's own COM is uncertain by
    about this much (a 30 cm wooden mallet's by about a millimetre), and a shift within it is no evidence
    of a non-uniform density."""
    max_delay_s: float = 0.05
    """Search range of time_delay [s], either sign."""
    prior_mass_factor: float = 4.0
    """A mass this many times above or below the geometry prior's is beyond what any material allows: a jointed
    part's is flagged doubtful, and a held body's refit with effects reads its prior's mass range as this wide."""
    unexplained_share: float = 0.2
    """A stretch holding at least this share of a non-white residual is reported as unexplained ..."""
    unexplained_chance: float = 0.01
    """... where noise with the residual's own spectrum puts as large a share in one stretch less often than
    this (a false stretch in about one clean recording in 100)."""
    window_s: float = 0.1
    """Windows of the Newton replay [s]."""
    joint_window_s: float = 0.6
    """Windows of the jointed refits and replays [s]. A passive joint force (b q', k q) is told from each
    window's free start state (q, q') only over longer windows than the identification's: in 0.3 s ones a
    drawer's damping came back 24-40 % low."""
    seed: int = 0
