"""The `twin` command: subcommands assembled from the stages' configurations, each stage's passed whole
(`--reconstruct.*`, `--decompose.*`, `--diagnosis.*`)."""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

import tyro

from pipelines.decompose import DecomposeConfig
from pipelines.diagnose import DiagnoseConfig
from pipelines.reconstruct.config import ReconstructConfig
from twin.output import INTERRUPTED


@dataclass(frozen=True)
class Build:
    """Build simulation-ready assets from a scan (or mesh) and robot recordings."""

    source: tyro.conf.Positional[Path]
    """Scan directory (nerfstudio layout) or mesh file (.obj .stl .ply .glb, metres, world frame)."""
    logs: tyro.conf.UseAppendAction[tuple[Path, ...]]
    """MCAP recording of an interaction (or a MIT pushing-dataset .h5/.json trial); repeat for several trials."""
    scan: tyro.conf.UseAppendAction[tuple[Path, ...]] = ()
    """Another scan session of the same object in another resting pose (turned over, on its side), merged with
    SOURCE's to see what one session cannot (under raised parts); repeat for more. SOURCE sets the placement."""
    holdout: Path | None = None
    """Recording kept out of the fit, used to measure predictive error."""
    output: Annotated[Path, tyro.conf.arg(aliases=("-o",))] = Path("out")
    """Output folder. twin's own files in it are replaced once the new build is complete; a folder holding
    files twin did not write is refused unless --force (they are never removed)."""
    force: bool = False
    """Write into an existing folder that holds files twin did not write; they are kept as they are (one that
    bears a name twin would write stops the build before anything moves)."""
    material: str | None = None
    """What the object is made of, in words ("beech wood", "painted MDF", "aluminium"; matched to the library
    in assets/materials.json). Default: the scan's object.json hint, else unknown."""
    mass: tuple[float, ...] = ()
    """KG [STD]: the object's weighed mass and, optionally, its standard uncertainty [kg] (default half of
    1 g or 1 %, whichever is larger: a kitchen scale). Used as a measurement in the fit."""
    mesh_units: Literal["m", "cm", "mm", "in"] | None = None
    """Length unit of a mesh SOURCE (default metres); e.g. mm for a CAD export."""
    name: str | None = None
    """Asset name (default: from object.json or the mesh file name)."""
    method: Literal["newton", "ls"] = "newton"
    """newton: the posterior (least squares' likelihood with the geometry prior), then the Newton fit from it,
    kept only when it predicts the held-out recording significantly better; ls: the posterior alone."""
    window_s: float = 0.1
    """Shooting-window length [s]."""
    max_iterations: int = 30
    """Levenberg-Marquardt iterations of the Newton fit."""
    optimizer: Literal["gauss-newton", "paper"] = "gauss-newton"
    """Newton fit: our Levenberg-Marquardt (default) or RigPI's own gradient scheme, for comparison."""
    vlm: str | None = None
    """OpenAI-compatible server asked for the material (e.g. http://127.0.0.1:8000/v1); key from TWIN_VLM_API_KEY.
    Any failure falls back to the offline prior."""
    vlm_model: str | None = None
    """Model name on the --vlm server (an image-capable one)."""
    kind: Literal["free", "sliding", "prismatic", "revolute"] | None = None
    """free: held and moved through the air; sliding: pushed across a support surface; prismatic,
    revolute: a drawer or door part on its joint. Default: chosen from the first recording's motion by BIC."""
    base_mesh: Path | None = None
    """Drawers and doors: mesh of the fixed base (world frame, metres), written with the part."""
    topic: tyro.conf.UseAppendAction[tuple[str, ...]] = ()
    """ROLE=/name: the topic for a role (pose, wrench, contact, joint); repeat per role.
    A contact topic may be a PoseStamped (its origin is the point, e.g. a pusher tip)."""
    frame: tyro.conf.UseAppendAction[tuple[str, ...]] = ()
    """ROLE=frame_id: the frame of wrench or contact messages whose header leaves it empty."""
    wrench_rotation: tuple[float, float, float, float] | None = None
    """Fixed sensor-to-world rotation of the wrench messages, quaternion x y z w (when the sensor frame is not in /tf)."""
    wrench_reaction: bool = False
    """The wrench messages give the force ON the sensor (a tool-mounted F/T sensor's reading): negate it."""
    push_min_speed: float = 0.01
    """Pushed objects: fit only windows where the object's median speed exceeds this [m/s]; lower it for slow
    pushes (a 10 mm/s pusher moving the object at 1-3 mm/s), whose friction the wrench balance then measures."""
    diagnose: bool = True
    """Run the diagnose stage after identification (--no-diagnose skips it)."""
    reconstruct: ReconstructConfig = ReconstructConfig()
    """The scan's fusion, segmentation and closing (one scan session; merged sessions keep their own)."""
    decompose: DecomposeConfig = DecomposeConfig()
    """The collision geometry: CoACD's settings and the hull limits."""
    diagnosis: DiagnoseConfig = DiagnoseConfig()
    """The diagnose stage: screening, refits, the choice (a held body's replay windows are --window-s)."""


@dataclass(frozen=True)
class Inspect:
    """List an MCAP recording's topics with their types, message counts, rates and time spans."""

    file: tyro.conf.Positional[Path]
    """The .mcap file (or a rosbag2 directory holding one)."""


@dataclass(frozen=True)
class Diagnose:
    """Find physics the identified model lacks: residual analysis, candidate effects, choice on held-out data.

    Updates OUT/asset.json (effects, unexplained, provenance.diagnose) and OUT/report.html.
    """

    output: tyro.conf.Positional[Path]
    """A directory written by `twin build`."""
    logs: tyro.conf.UseAppendAction[tuple[Path, ...]] = ()
    """MCAP recording of an interaction; repeat for several trials."""
    holdout: Path | None = None
    """MCAP recording kept out of the fit; chooses among candidates (else time-blocked cross-validation)."""
    diagnosis: DiagnoseConfig = DiagnoseConfig()
    """The diagnose stage: screening, refits, the choice (a held body's replay windows are the build's)."""


@dataclass(frozen=True)
class Synth:
    """Make a sample with known truth: an RGB-D scan and two recordings of a held object or a jointed part."""

    output: Annotated[Path, tyro.conf.arg(aliases=("-o",))]
    """Folder to write (scan/, trial.mcap, heldout.mcap, truth.json); an existing one needs --force."""
    force: bool = False
    """Replace what an earlier `twin synth` wrote into OUTPUT (files it did not write are kept)."""
    object: Literal["drawer", "cabinet_door", "oven_door"] | None = None
    """A part on a joint (RigPI's drawer, cabinet door, oven door analogues) instead of a held --shape."""
    shape: Literal["cube", "sphere"] = "cube"
    size_m: float = 0.04
    """Cube edge or sphere diameter [m]."""
    mass_kg: float = 0.02
    material: str = "pla_printed"
    seed: int = 0
    effect: Literal["none", "sensor_bias", "time_delay", "viscous_damping", "quadratic_drag",
                    "nonuniform_density", "spring", "stribeck_friction"] = "none"
    """Physics to conceal in both recordings (the model twin starts from lacks it); with --object:
    viscous_damping, spring or stribeck_friction on the joint."""
    effect_magnitude: float = 2.0
    """Size of the concealed effect as a multiple of the sensor's noise (see pipelines/synth/effects.py)."""
    engine: Literal["newton", "mujoco"] = "newton"
    """Simulator that makes the recordings: twin's own Newton models, or MuJoCo's (a PD-servoed robot, joint
    frictionloss, its integrator): a truth the identification does not share."""
    wrench_frame: Literal["gripper", "world"] = "gripper"
    """Frame of the wrench messages: the sensor's, turning with the gripper, or world."""
    furniture: bool = False
    """With --object: scan the part as it stands in its furniture (a chest, a cabinet, an oven), from the front."""
    pushed: bool = False
    """Instead of a held --shape: a 10 x 10 x 1 cm, 0.75 kg block pushed twice across a table (mu 0.3),
    written as block.obj (the mesh to build from), trial.mcap, heldout.mcap and truth.json; with
    --engine mujoco, MuJoCo's contact and a PD-servoed pusher, the force in the sensor's axes (gripper) or
    world's."""


@dataclass(frozen=True)
class Bench:
    """Benchmarks that print a table.

    sample: cold and warm builds of a synthetic sample against its truth.
    paper: RigPI's cube, sphere and apple, held and moved, then its drawer, cabinet door and oven door; several noise draws each.
    priors: RigPI's six objects: prior error (library, the paper's VLM answers, fusion) and whether C holds the truth.
    throughput: time per identification iteration for 1 and many objects batched, on --device.
    crlb: spread of the estimates over --draws noise draws against the Cramer-Rao bound.
    mujoco: paper's recordings identified by mujoco.sysid (pseudo-inertia) and by ours, side by side.
    reconstruct: scans of real meshes and primitives (3-30 cm, three noise levels) against their truth; real frames.
    push: synthetic pushes with known friction (--seeds of them): friction, mass and yaw inertia errors.
    push-real: the MIT block pushes: friction per trial and its spread, quasi-static estimate, predictive validity.
    push-mit: the MIT pushing dataset's trials (mass known): friction per trial, spread, predictive validity.
    diagnose: --concealed recordings with a hidden effect of random size and --clean ones, shuffled: effect found?
    furniture: drawers and doors scanned in their furniture from the front (three noise levels) against the truth.
    fuzz: seconds until a wrong SOURCE, OUT, material or topic is reported; then every reader fed --inputs
      seeded mutations of a valid file: outcomes counted, uncaught ones listed.
    workshop: the Workshop Tools benchmark (six real tools) at the authors' noise levels, --seeds draws each:
      our estimators beside the published OLS, GEO and HPS, on the authors' metrics.
    """

    what: tyro.conf.Positional[Literal["sample", "paper", "priors", "throughput", "crlb", "mujoco", "reconstruct",
                                       "push", "push-real", "push-mit", "diagnose", "fuzz", "furniture",
                                       "workshop"]]
    sample: Path = Path("samples/cube")
    """Sample directory made by `twin synth` (scan/, trial.mcap, heldout.mcap, truth.json)."""
    methods: tuple[Literal["newton", "ls"], ...] = ("newton", "ls")
    seeds: int = 5
    """Noise draws per object (paper, mujoco); seeds per case (diagnose --push-synth); scans per part and level
    (furniture)."""
    blocks: tuple[str, ...] = ()
    """push-real, diagnose --push-real: block folders to run (St_block, Al_block, Plastic_block; default all)."""
    offsets_only: bool = False
    """push-real: only the quasi-static friction of every bag under three force-offset models (no Newton fits)."""
    paper_optimizer: bool = False
    """Also run RigPI's own optimizer on the same recordings (paper; adds about 20 s per draw)."""
    vlm_starts: bool = False
    """Also run the Newton fit alone from far starts like the paper's VLM guesses (paper)."""
    draws: int = 20
    """Noise draws per object (crlb)."""
    device: str = "cpu"
    """Warp device for throughput, e.g. cuda:0."""
    objects: tuple[int, ...] = (1, 1024)
    """Objects batched per run (throughput)."""
    quick: bool = False
    """A subset that runs in about a minute (reconstruct)."""
    sessions_only: bool = False
    """reconstruct: only the objects also scanned a second time, turned over (the two-session columns)."""
    names: tuple[str, ...] = ()
    """reconstruct: objects to run, named as in its table (e.g. "Allen Key" "cube 30 cm"; default all)."""
    noise: tuple[str, ...] = ()
    """reconstruct, furniture: depth-noise levels to run (low, high, sensor; default all), without the
    noise-free scans."""
    levels: tuple[Literal["No", "Low", "Mod", "High"], ...] = ("No", "Low", "Mod", "High")
    """workshop: the authors' noise levels to run."""
    identify_with: Literal["ls", "newton"] = "ls"
    """workshop: ls, the posterior a build keeps without a held-out recording; newton, the build's whole path
    (the Newton fit from the posterior too; about 10 s a run)."""
    parts: Literal["segmentation", "geometry", "none"] = "segmentation"
    """workshop: per-part densities over the authors' segmentation, over parts found from geometry alone, or a
    uniform density."""
    jointed_only: bool = False
    """paper: only the drawer, cabinet door and oven door."""
    engine: Literal["newton", "mujoco", "both"] = "both"
    """paper, push, diagnose: the simulator that makes the recordings: twin's own Newton models (those identification fits),
    MuJoCo (a PD-servoed robot; it follows the same references only as closely as its servos do), or both,
    one row each; a target is met when it holds on every engine."""
    concealed: int = 40
    """Recordings with a concealed effect (diagnose)."""
    clean: int = 10
    """Recordings without one (diagnose)."""
    duration_s: float = 3.0
    """Length of each recording [s] (diagnose)."""
    without_holdout: bool = False
    """diagnose: as a build without --holdout, the diagnosis choosing on the trial alone (the held-out
    recording scores the true model only)."""
    push_late_s: float = 0.0
    """diagnose: start each push recording's pose track this much later [s], as a recording that began at
    another moment (a push's windows are tiled from its first pose: docs/pushes.md)."""
    cases: tuple[int, ...] = ()
    """diagnose: only these case indices of the shuffled list (the same recordings as the full run; default all)."""
    workshop: bool = False
    """Diagnose the workshop-tools recordings of ../shared/data instead of synthetic ones (diagnose)."""
    push_real: bool = False
    """Diagnose the MIT block pushes of ../shared/data (odd trials fitted, even held out; --blocks picks)
    instead of synthetic recordings (diagnose)."""
    inputs: int = 2000
    """fuzz: mutated inputs per reader."""
    readers: tuple[str, ...] = ()
    """fuzz: readers to run (default all; names as in its table)."""
    push_synth: bool = False
    """Diagnose synthetic pushes with a concealed drag, a concealed delay or nothing, --seeds of each (diagnose)."""


def _log(message: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {message}", flush=True)


def _weighed(values: tuple[float, ...]) -> tuple[float, float] | None:
    """--mass KG [STD] as (kg, standard uncertainty); without STD a kitchen scale's: +-max(1 g, 1 %) at 2 sigma."""
    if not values:
        return None
    if len(values) > 2:
        raise ValueError(f"--mass {' '.join(map(str, values))}: expected KG or KG STD")
    return (values[0], values[1] if len(values) == 2 else max(0.001, 0.01 * abs(values[0])) / 2)


def _run_build(args: Build) -> None:
    from twin.build import BuildConfig, build

    config = BuildConfig(
        source=args.source, scans=args.scan, logs=args.logs, output=args.output, holdout=args.holdout, material=args.material,
        name=args.name, method=args.method, window_s=args.window_s, max_iterations=args.max_iterations,
        optimizer=args.optimizer,
        vlm=args.vlm, vlm_model=args.vlm_model, kind=args.kind, base_mesh=args.base_mesh,
        topics=_role_map(args.topic, "--topic"), frames=_role_map(args.frame, "--frame"),
        wrench_rotation_xyzw=args.wrench_rotation, wrench_reaction=args.wrench_reaction,
        push_min_speed_m_s=args.push_min_speed, diagnose=args.diagnose, force=args.force,
        mesh_units=args.mesh_units, mass_kg=_weighed(args.mass), reconstruct=args.reconstruct,
        decompose=args.decompose, diagnosis=args.diagnosis,
    )
    build(config, log=_log)


def _role_map(items: tuple[str, ...], flag: str) -> tuple[tuple[str, str], ...]:
    """ROLE=value options as (role, value) pairs; a malformed one is a ValueError naming it."""
    pairs = []
    for item in items:
        role, sep, value = item.partition("=")
        if not sep or not role or not value:
            raise ValueError(f"{flag} {item!r}: expected ROLE=VALUE, e.g. {flag} wrench=/netft_data")
        pairs.append((role, value))
    return tuple(pairs)


def _run_inspect(args: Inspect) -> None:
    from pipelines.logs import inspect_recording

    rows = inspect_recording(args.file)
    width = max([len("topic")] + [len(r.topic) for r in rows])
    type_width = max([len("type")] + [len(r.type) for r in rows])
    print(f"{args.file}")
    print(f"{'topic':<{width}}  {'type':<{type_width}}  {'count':>7}  {'rate Hz':>8}  {'start s':>16}  {'span s':>8}")
    for r in rows:
        print(f"{r.topic:<{width}}  {r.type:<{type_width}}  {r.count:>7}  {r.rate_hz:>8.2f}  "
              f"{r.t_start_s:>16.3f}  {r.t_end_s - r.t_start_s:>8.3f}")


def _run_synth(args: Synth) -> None:
    import trimesh

    from twin.output import check_output, staged_output

    check_output(args.output, args.force, replace_own=False, made_by="synth")

    if args.pushed:
        from pipelines.synth.mujoco_push import PushedSampleConfig, make_pushed_sample
        from pipelines.synth.push import PushConfig

        frame = "sensor" if args.engine == "mujoco" and args.wrench_frame == "gripper" else "world"
        _log(f"synthesising a pushed block into {args.output} ({args.engine}, force in {frame} axes)")
        with staged_output(args.output, args.force, replace_own=False, made_by="synth") as tmp:
            make_pushed_sample(tmp, PushedSampleConfig(push=PushConfig(seed=args.seed, offset_m=0.015)),
                               engine=args.engine, wrench_frame=frame)
        _log(f"wrote {args.output}")
        return

    if args.object is not None:
        from pipelines.synth.effects import concealed_joint_effect
        from pipelines.synth.held import SensorNoise
        from pipelines.synth.jointed import jointed_paper_objects
        from pipelines.synth.sample import JointedSampleConfig, make_jointed_sample

        effect = None
        if args.effect != "none":
            import numpy as np

            effect = concealed_joint_effect(args.effect, args.effect_magnitude, np.random.default_rng(args.seed),
                                            jointed_paper_objects()[args.object], SensorNoise())
            _log(f"concealing {effect.name} {effect.params}")
        _log(f"synthesising {args.object} into {args.output}")
        with staged_output(args.output, args.force, replace_own=False, made_by="synth") as tmp:
            make_jointed_sample(tmp, JointedSampleConfig(object=args.object, seed=args.seed, effect=effect,
                                                         furniture=args.furniture),
                                engine=args.engine, wrench_frame=args.wrench_frame)
        _log(f"wrote {args.output}")
        return

    from pipelines.synth.sample import HeldSampleConfig, make_held_sample

    if args.shape == "cube":
        mesh = trimesh.creation.box((args.size_m,) * 3)
    else:
        mesh = trimesh.creation.icosphere(subdivisions=4, radius=args.size_m / 2)
    effect = None
    if args.effect != "none":
        import numpy as np

        from pipelines.synth.effects import concealed_effect
        from pipelines.synth.held import SensorNoise

        effect = concealed_effect(args.effect, args.effect_magnitude, np.random.default_rng(args.seed), SensorNoise())
        _log(f"concealing {effect.name} {effect.params}")
    config = HeldSampleConfig(name=args.shape, material=args.material, mass_kg=args.mass_kg, seed=args.seed,
                              effect=effect)
    _log(f"synthesising {args.shape} into {args.output}")
    with staged_output(args.output, args.force, replace_own=False, made_by="synth") as tmp:
        make_held_sample(mesh, tmp, config, engine=args.engine, wrench_frame=args.wrench_frame)
    _log(f"wrote {args.output}")


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("twin")
    except PackageNotFoundError:
        return "unknown (not installed)"


def _interrupt(signum, frame) -> None:
    # SIGTERM unwinds like Ctrl-C, so every temporary folder is removed on the way out; the flag is for an
    # interrupt that lands in a C extension's import (Python turns it into an ImportError) or in a callback
    # (Python prints it and goes on)
    INTERRUPTED.set()
    raise KeyboardInterrupt


def _quiet_swallowed_interrupt(unraisable) -> None:
    if not INTERRUPTED.is_set():
        sys.__unraisablehook__(unraisable)


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"twin: warning: {' '.join(str(message).split())}", file=sys.stderr, flush=True)


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


def main(argv: list[str] | None = None) -> int:
    """Entry point: errors become one line `twin: error: ...` on stderr and exit code 1; an interrupt
    (Ctrl-C, SIGTERM) one line and exit code 130."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] in (["--version"], ["-V"]):
        print(f"twin {_version()}")
        return 0
    command = tyro.extras.subcommand_cli_from_dict(
        {"build": Build, "diagnose": Diagnose, "inspect": Inspect, "synth": Synth, "bench": Bench}, args=argv)
    warnings.showwarning = _show_warning  # one line each, like the errors, not the file and line of the check
    in_main_thread = threading.current_thread() is threading.main_thread()
    INTERRUPTED.clear()
    previous = {sig: signal.signal(sig, _interrupt) for sig in (signal.SIGINT, signal.SIGTERM)} if in_main_thread else {}
    previous_hook, sys.unraisablehook = sys.unraisablehook, _quiet_swallowed_interrupt
    try:
        _dispatch(command)
        if INTERRUPTED.is_set():
            raise KeyboardInterrupt
    except BaseException as exc:  # noqa: BLE001 - every way out is one line
        if INTERRUPTED.is_set() or isinstance(exc, KeyboardInterrupt):
            print("twin: interrupted; outputs left as they were", file=sys.stderr)
            return 130
        if isinstance(exc, SystemExit) or os.environ.get("TWIN_DEBUG"):
            raise
        if isinstance(exc, (ValueError, RuntimeError, OSError)):
            print(f"twin: error: {_one_line(exc)}", file=sys.stderr)
        else:  # a user gets one line, a developer the traceback on request
            print(f"twin: error: internal error ({type(exc).__name__}: {_one_line(exc)}); "
                  f"TWIN_DEBUG=1 shows where", file=sys.stderr)
        return 1
    finally:  # main may be called again in the same process (tests, a notebook): nothing of this run stays set
        INTERRUPTED.clear()
        sys.unraisablehook = previous_hook
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    return 0


def _dispatch(command) -> None:
    if not isinstance(command, (Build, Inspect)):  # a build checks its inputs first and loads warp after
        from twin.stages import quiet_warp

        quiet_warp()
    if isinstance(command, Build):
        _run_build(command)
    elif isinstance(command, Inspect):
        _run_inspect(command)
    elif isinstance(command, Diagnose):
        from twin.diagnose import DiagnoseRunConfig, diagnose_output

        diagnose_output(DiagnoseRunConfig(command.output, command.logs, command.holdout, command.diagnosis),
                        log=_log)
    elif isinstance(command, Synth):
        _run_synth(command)
    else:
        _run_bench(command)


BENCHMARKS_MISSING = "benchmarks/: twin bench runs from a source checkout of twin (the benchmarks are not installed)"


def _benchmark(name: str):
    """The module benchmarks.NAME of the source checkout twin runs from (the `benchmarks/` folder beside the
    `twin` package), its root put on sys.path; an installed twin ships no benchmarks: a RuntimeError."""
    import importlib

    import twin

    root = Path(twin.__file__).resolve().parents[1]
    if not (root / "benchmarks" / f"{name}.py").is_file():
        raise RuntimeError(BENCHMARKS_MISSING)
    if str(root) not in sys.path:
        sys.path.insert(0, str(root))
    return importlib.import_module(f"benchmarks.{name}")


def _run_bench(command: Bench) -> None:
    if command.what == "sample":
        _benchmark("sample").bench_sample(command.sample, command.methods)
    elif command.what == "diagnose":
        diagnose = _benchmark("diagnose")
        if command.workshop:
            diagnose.bench_diagnose_workshop()
        elif command.push_real:
            diagnose.bench_diagnose_push_real(command.blocks)
        elif command.push_synth:
            diagnose.bench_diagnose_push_synth(command.seeds)
        else:
            diagnose.bench_diagnose(command.concealed, command.clean, command.duration_s, cases=command.cases,
                                    engine=command.engine, with_holdout=not command.without_holdout,
                                    push_late_s=command.push_late_s)
    elif command.what == "workshop":
        _benchmark("workshop").bench_workshop(command.seeds, command.levels, method=command.identify_with,
                                              parts=command.parts)
    elif command.what == "furniture":
        _benchmark("furniture").bench_furniture(command.noise, command.seeds)
    elif command.what == "fuzz":
        _benchmark("fuzz").bench_fuzz(command.inputs, command.readers, sample=command.sample)
    elif command.what == "crlb":
        _benchmark("crlb").bench_crlb(command.draws)
    elif command.what == "throughput":
        _benchmark("throughput").bench_throughput(command.device, command.objects)
    elif command.what == "mujoco":
        _benchmark("mujoco").bench_mujoco(command.seeds)
    elif command.what == "reconstruct":
        _benchmark("reconstruct").bench_reconstruct(quick=command.quick, sessions_only=command.sessions_only,
                                                    names=command.names, noises=command.noise)
    elif command.what == "push":
        _benchmark("push").bench_push(command.seeds, engine=command.engine)
    elif command.what == "push-real":
        push = _benchmark("push")
        if command.offsets_only:
            push.bench_push_offsets()
        else:
            push.bench_push_real(blocks=command.blocks)
    elif command.what == "push-mit":
        _benchmark("push_mit").bench_push_mit()
    elif command.what == "priors":
        _benchmark("priors").bench_priors()
    elif command.jointed_only:
        _benchmark("paper_jointed").bench_paper_jointed(command.seeds, engine=command.engine)
    else:
        _benchmark("paper").bench_paper(command.seeds, paper_optimizer=command.paper_optimizer,
                                        from_vlm_starts=command.vlm_starts, engine=command.engine)


def entry() -> None:
    """The `twin` command. An interrupted run leaves at once with 130: its clean-up already ran while the
    interrupt unwound, and the interpreter's own teardown after an interrupted native call (Open3D, Warp)
    can end the process with 1 instead."""
    code = main()
    if code == 130:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(130)
    sys.exit(code)


if __name__ == "__main__":
    entry()
