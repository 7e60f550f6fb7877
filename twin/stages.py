"""What the stages of `twin build` share: the configuration and its errors, the stage timer, the material
choice, and the two records that pass between the stages (`Prepared`, what every kind starts from, and
`Identified`, what the writing stage needs of a kind).

Kept light: the heavy pipelines (identification, diagnosis, priors) load inside the functions that run
them, after `twin build` has checked its inputs.
"""

from __future__ import annotations

import os
import sys
import time
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Literal

import numpy as np

from assets import Asset, Estimate, Material
from assets.materials import MATCH_THRESHOLD, match_material, material_range, suggest_materials
from pipelines.decompose import DecomposeConfig
from pipelines.diagnose import DiagnoseConfig
from pipelines.reconstruct.config import ReconstructConfig
from twin.summary import bounds_flags, doubtful_flags, dominated_flags
from twin.write import mesh_geometry

if TYPE_CHECKING:
    import trimesh

    from assets import Fit, Pose
    from assets.recording import Recording
    from pipelines.decompose import ConvexParts
    from pipelines.identify import KindDetection
    from pipelines.priors import Prior


class BuildError(RuntimeError):
    """A build failed for a reason the user can act on; the message names the file."""


@dataclass(frozen=True)
class BuildConfig:
    """Everything a build depends on; printed into asset.json provenance."""

    source: Path
    logs: tuple[Path, ...]
    scans: tuple[Path, ...] = ()
    """Further scan sessions of the object, registered to SOURCE's and intersected with it (pipelines/sessions)."""
    output: Path = Path("out")
    holdout: Path | None = None
    material: str | None = None
    name: str | None = None
    method: Literal["newton", "ls"] = "newton"
    window_s: float = 0.1
    max_iterations: int = 30
    optimizer: Literal["gauss-newton", "paper"] = "gauss-newton"
    cache_dir: Path = Path.home() / ".cache" / "twin"
    vlm: str | None = None
    vlm_model: str | None = None
    kind: Literal["free", "sliding", "prismatic", "revolute"] | None = None
    base_mesh: Path | None = None
    diagnose: bool = True
    """Look for missing physics after identification (pipelines/diagnose): free, pushed and jointed bodies."""
    topics: tuple[tuple[str, str], ...] = ()
    """(role, topic) overrides for reading the recordings."""
    frames: tuple[tuple[str, str], ...] = ()
    """(role, frame id) for wrench or contact messages whose header leaves it empty."""
    wrench_rotation_xyzw: tuple[float, float, float, float] | None = None
    wrench_reaction: bool = False
    """The wrench messages give the force on the sensor (the object's reaction): negate them."""
    push_min_speed_m_s: float = 0.01
    """Pushed objects: a window is fitted only where the object's median speed exceeds this [m/s]."""
    force: bool = False
    """Write into an existing folder that holds files twin did not write (they are kept)."""
    mesh_units: str | None = None
    """Length unit of a mesh SOURCE ("m", "cm", "mm", "in"); None: metres."""
    mass_kg: tuple[float, float] | None = None
    """The object's weighed mass and its standard uncertainty [kg], a measurement the fit uses."""
    reconstruct: ReconstructConfig = ReconstructConfig()
    """The scan's fusion and closing (a single scan session; merged sessions keep their own settings)."""
    decompose: DecomposeConfig = DecomposeConfig()
    """The collision geometry's convex decomposition (CoACD)."""
    diagnosis: DiagnoseConfig = DiagnoseConfig()
    """The diagnose stage's settings; a held body's replay windows are `window_s`."""

    def read(self, path: Path):
        """One recording, read with this build's topic, frame and rotation options (MCAP), or a
        MIT pushing-dataset trial (.h5 or .json, whose layout fixes roles and frames)."""
        from pipelines.logs import read_recording  # the MCAP readers: loaded once a build reads its logs

        if Path(path).suffix in (".h5", ".json"):
            from pipelines.push_dataset import read_push_trial

            return read_push_trial(path)

        return read_recording(path, dict(self.topics), dict(self.frames), self.wrench_rotation_xyzw,
                              self.wrench_reaction)


@dataclass
class StageTimer:
    """Wall time per stage, reported through `log`; on a terminal a spinner with the elapsed time shows
    that a long stage (reconstruction, decomposition, identification, diagnosis) is alive."""

    log: Callable[[str], None]
    seconds: dict = field(default_factory=dict)
    live: bool = field(default_factory=lambda: sys.stderr.isatty() and not os.environ.get("CI"))
    """Show the spinner: on a terminal, never in a CI log."""
    started: float = field(default_factory=time.perf_counter)
    """When the timer was made: the build's start, for its total."""

    def run(self, name: str, fn, *args, **kwargs):
        self.log(f"{name} ...")
        t0 = time.perf_counter()
        with _spinner(name) if self.live else nullcontext():
            out = fn(*args, **kwargs)
        self.seconds[name] = time.perf_counter() - t0
        self.log(f"{name} done in {self.seconds[name]:.1f} s")
        return out

    def elapsed(self) -> float:
        """Seconds since the timer was made."""
        return time.perf_counter() - self.started


@contextmanager
def _spinner(name: str):
    from rich.console import Console
    from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    # transient and on stderr: the log lines on stdout stay as they are, in a file or a CI log alike
    with Progress(SpinnerColumn(), TextColumn("{task.description}"), TimeElapsedColumn(),
                  console=Console(stderr=True), transient=True, redirect_stdout=True) as progress:
        progress.add_task(name, total=None)
        yield


def quiet_warp() -> None:
    """Warp without its load and CUDA-driver chatter: a build's log is its stage lines, its errors one line each."""
    import warp as wp

    wp.config.quiet = True
    wp.config.log_level = wp.LOG_WARNING  # no per-module load lines in the progress log
    # Warp's native init prints a CUDA-driver notice straight to fd 2 on machines without a GPU: errors are
    # one line each, so the notice is kept out (a GPU machine loses nothing, a failed init still raises)
    saved, devnull = os.dup(2), os.open(os.devnull, os.O_WRONLY)
    try:
        sys.stderr.flush()
        os.dup2(devnull, 2)
        wp.init()
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)


@dataclass(frozen=True)
class MaterialChoice:
    """The library entry the prior starts from, and how the user's words led to it (asset.json `material`)."""

    entry: object | None
    """The `MaterialRange`, or None for the wide `unknown` prior."""
    text: str | None
    source: str
    """"named" (--material), "hint" (object.json), "unmatched" (a hint the library does not know), "vlm",
    or "library" (no words given)."""
    score: float | None

    def material(self, name: str, density: float, friction: float) -> Material:
        return Material(name, density, friction, text=self.text, source=self.source, match_score=self.score)


def choose_material(named: str | None, hint: str | None, log) -> MaterialChoice:
    """--material must match the library (checked before the build starts); an object.json hint that matches
    nothing is a warning and the wide prior, never a failed build."""
    if named is not None:
        match = match_material(named)
        return MaterialChoice(material_range(named), named, "named", match.score if match.name else None)
    if hint is None:
        return MaterialChoice(None, None, "library", None)
    match = match_material(hint)
    if match.name is None or match.score < MATCH_THRESHOLD:
        log(f"warning: object.json material {hint!r} matches nothing in the library (nearest: "
            f"{', '.join(suggest_materials(hint))}); using the wide prior of an unknown material")
        return MaterialChoice(None, hint, "unmatched", 0.0)
    if match.how != "exact":
        log(f"material {hint!r} read as {match.name} ({match.how}, match {match.score:.2f})")
    return MaterialChoice(material_range(match.name), hint, "hint", match.score)


@dataclass(frozen=True)
class Prepared:
    """What the shared stages made of the inputs, before the kind's identification: every kind's one argument."""

    config: BuildConfig
    trials: list[Recording]
    holdout: Recording | None
    detection: KindDetection
    mesh: trimesh.Trimesh
    """The watertight object mesh in the object frame (origin at its centre of mass)."""
    placement: Pose
    """The object frame in world."""
    parts: ConvexParts
    prior: Prior
    choice: MaterialChoice
    name: str
    scan_stats: dict
    timer: StageTimer
    log: Callable[[str], None]


@dataclass(frozen=True)
class Identified:
    """What a kind's identification and diagnosis hand to the writing stage."""

    asset: Asset
    """The asset to export: everything but its files and full provenance."""
    provenance: dict
    """The kind's provenance entries (identify, diagnose, ...), placed after `kind` in asset.json."""
    decompose: dict
    """provenance → decompose."""
    validate: Callable[[Asset, Path, dict], dict]
    """(asset, staging folder, files) -> provenance → validation: the exports reloaded and compared."""
    replay: Callable[[Asset, Path, dict], dict | None]
    """(asset, staging folder, files) -> provenance → heldout_replay (None: no entry)."""
    report: tuple | None = None
    """(loss history, traces, diagnosis traces) for report.html; None: no report."""
    base_mesh: Path | None = None
    """A mesh file written as meshes/base.obj (a jointed part's fixed base)."""
    note: str = ""
    """Added to the closing "wrote OUT/" line."""


@contextmanager
def kind_hint(detection, recording):
    """An identification that fails on a kind the motion only suggested names the option that would help:
    a pushed block read as held, say, ends in a singular fit rather than in anything a user can act on."""
    try:
        yield
    except (np.linalg.LinAlgError, ValueError, FloatingPointError) as exc:
        if detection.forced or isinstance(exc, BuildError):
            raise
        others = [k for k in ("free", "sliding", "prismatic", "revolute") if k != detection.kind]
        raise BuildError(f"{recording.path}: identification as a {detection.kind} body failed ({exc}); the kind was "
                         f"read from the motion: if the object was not {detection.kind}, pass --kind "
                         f"{'|'.join(others)}") from exc


def weighed_where_prior(theta, weighed: tuple[float, float] | None):
    """A mass the recordings could not determine is the user's weighing, said so, rather than the prior's."""
    if weighed is None or theta.mass.source != "prior":
        return theta
    mass, std = weighed
    return replace(theta, mass=Estimate(mass, std, source="weighed", interval95=(mass - 1.96 * std, mass + 1.96 * std),
                                        prior=theta.mass.prior))


def body_asset(p: Prepared, theta, fit: Fit, diagnosis, dominated: set, provenance: dict) -> Asset:
    """The asset of a free or pushed body; the exporters read the identification's choices (a pushed
    object's support) from its provenance."""
    return Asset(
        name=p.name,
        kind=p.detection.kind,
        placement=p.placement,
        theta=theta,
        geometry=mesh_geometry(p.parts, p.scan_stats.get("extent")),
        material=p.choice.material(p.prior.material.name, float(theta.mass.value / p.mesh.volume),
                                   theta.friction.value),
        fit=fit,
        effects=diagnosis.effects if diagnosis else (),
        unexplained=diagnosis.unexplained if diagnosis else (),
        flags=(bounds_flags(theta, p.prior.lower, p.prior.upper) + dominated_flags(dominated)
               + doubtful_flags(diagnosis.doubtful if diagnosis else ())),
        provenance=provenance,
    )


def log_diagnosis(diagnosis, log) -> None:
    """The diagnosis in the progress log: residual findings, effects, the held-out RMSE, what is unexplained."""
    for line in diagnosis.findings[:6]:
        log(f"  residual: {line}")
    fits = diagnosis.fits
    for e in diagnosis.effects:
        log(f"  effect {e.name}: {e.params}")
    floor = (f" (the sensors' noise alone: about {1000 * diagnosis.noise_floor['rmse_position_m']:.3f} mm)"
             if diagnosis.noise_floor else "")
    if diagnosis.effects:
        log(f"  held-out position RMSE {1000 * fits['before'].rmse_position_m:.3f} -> "
            f"{1000 * fits['after'].rmse_position_m:.3f} mm{floor}")
    else:
        log(f"  no effect improves the held-out prediction, {1000 * fits['after'].rmse_position_m:.3f} mm{floor}")
    for u in diagnosis.unexplained:
        log(f"  unexplained: {u['summary']}")
    if diagnosis.doubtful:
        log(f"  doubtful (a mismatch may have corrupted them): {', '.join(diagnosis.doubtful)}")
