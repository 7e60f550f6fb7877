"""What a build says in words at its end and in its report: which estimate was kept and why, what was
measured and what is prior, and the flags a user must see beside the numbers."""

from __future__ import annotations

import numpy as np

from assets import MASS, MOMENTS

_ESTIMATES = {"newton": "the Newton fit", "least_squares": "least squares", "baseline": "the prior",
              "prior": "the prior", "posterior": "the posterior (the recordings with the geometry prior)"}


def dominated_flags(dominated: set) -> tuple[dict, ...]:
    """The inertial components the recordings could not determine (`HeldIdentification.prior_dominated`)."""
    if not dominated:
        return ()
    return ({"parameter": "inertial", "problem": "prior-dominated: the recordings could not determine these; the "
             "values are mostly the geometry prior's", "components": sorted(dominated)},)


def doubtful_flags(doubtful) -> tuple[dict, ...]:
    """The parameters a mismatch the diagnosis could not explain may have corrupted (`Diagnosis.doubtful`)."""
    if not doubtful:
        return ()
    return ({"parameter": "diagnosis", "problem": "doubtful: a mismatch no candidate explains may have corrupted "
             "these; they are not to be taken as measured", "components": sorted(doubtful)},)


def disagreement_flags(doubtful, disagreement: dict) -> tuple[dict, ...]:
    """The determined quantities on which the Newton fit and least squares disagree
    (`JointedIdentification.doubtful`): a force neither models bends them."""
    if not doubtful:
        return ()
    return ({"parameter": "identification", "problem": "doubtful: the Newton fit and least squares disagree on these, "
             "a force neither models may have bent them; they are not to be taken as measured",
             "components": sorted(doubtful), "apart": {n: disagreement[n] for n in sorted(doubtful)}},)


def bounds_flags(theta, lower, upper) -> tuple[dict, ...]:
    """A measured mass or principal moment outside the geometry prior's bounds C.

    The bounds hold 99 % of what the mesh and material allow, so a value outside them is either a
    surprising object (a hidden dense insert, a hollow part) or a fit that absorbed something else (a
    misdetected kind, a wrench bias): either way it must not pass as an ordinary measurement.
    """
    flags = []
    if theta.mass.source == "measured" and not lower[MASS] <= theta.mass.value <= upper[MASS]:
        flags.append({"parameter": "mass", "problem": "outside the geometry prior's bounds",
                      "value": float(theta.mass.value), "bounds": [float(lower[MASS]), float(upper[MASS])]})
    if theta.inertia.source == "measured" and len(lower) >= MOMENTS.stop:
        moments = np.diag(np.asarray(theta.inertia.value, dtype=float))
        low, high = np.asarray(lower, dtype=float)[MOMENTS], np.asarray(upper, dtype=float)[MOMENTS]
        outside = [i for i in range(3) if not low[i] <= moments[i] <= high[i]]
        if outside:
            flags.append({"parameter": "inertia", "problem": "diagonal moments outside the geometry prior's bounds",
                          "axes": ["xyz"[i] for i in outside], "value": moments.tolist(),
                          "bounds": [low.tolist(), high.tolist()]})
    return tuple(flags)


def extent_flags(extent: dict | None) -> tuple[dict, ...]:
    """A part whose depth no view saw (a door or drawer front scanned in its furniture) was closed with an
    assumed thickness: its volume, mass prior and inertia rest on that assumption."""
    if not extent or not extent.get("assumed"):
        return ()
    return tuple({"parameter": "geometry", "problem": f"{name.removesuffix('_m')} assumed, not seen",
                  **({"value": v.get("value"), "std": v.get("std"), "from": v.get("from")} if isinstance(v, dict) else {})}
                 for name, v in extent["assumed"].items())


def flag_line(flag: dict) -> str:
    value = flag.get("value")
    bounds = flag.get("bounds")
    if flag.get("parameter") == "mass" and bounds:
        return f"mass {value:.4g} kg is {flag['problem']} [{bounds[0]:.4g}, {bounds[1]:.4g}] kg"
    if flag.get("parameter") == "geometry" and flag.get("value") is not None:
        return (f"{flag['problem']}: {1000 * flag['value']:.1f} +- {1000 * (flag.get('std') or 0):.1f} mm "
                f"({flag.get('from', '')})")
    if flag.get("components"):
        return f"{flag.get('parameter', '?')}: {flag.get('problem', '')} ({', '.join(flag['components'])})"
    return f"{flag.get('parameter', '?')}: {flag.get('problem', '')}"


def summary_lines(doc: dict) -> list[str]:
    """The build's closing words from its asset.json document."""
    theta, provenance = doc.get("theta", {}), doc.get("provenance", {})
    identify = provenance.get("identify", {})
    lines = []
    selected = identify.get("selected")
    if identify.get("choice"):
        lines.append(f"kept the {identify['choice']}")
    elif selected:
        fits = identify.get("heldout_fits") or identify.get("fits", {}).get("holdout") or {}
        rmse = {k: v.get("rmse_position_m") for k, v in fits.items() if isinstance(v, dict)}
        if selected in rmse and len(rmse) > 1:
            others = ", ".join(f"{_ESTIMATES.get(k, k)} {1000 * v:.3f} mm" for k, v in rmse.items()
                               if k != selected and v is not None)
            why = (f"it predicts the held-out recording best ({1000 * rmse[selected]:.3f} mm position RMSE; "
                   f"{others})")
        else:
            why = "the default method; a held-out recording (--holdout) would let the estimates compete"
        lines.append(f"kept {_ESTIMATES.get(selected, selected)}: {why}")
    if identify.get("friction_from"):
        lines.append(f"friction from {identify['friction_from']}")
    replay = provenance.get("heldout_replay", {})
    mujoco, newton = (replay.get(k, {}).get("rmse_position_m") for k in ("mujoco", "newton"))
    if mujoco is not None and newton:
        floor = replay.get("noise_floor_m")
        lines.append(f"the exported MJCF replays the held-out recording in MuJoCo at {1000 * mujoco:.3f} mm "
                     f"({mujoco / newton:.2f}x Newton's" + (f", {mujoco / floor:.2f}x the sensors' noise alone)"
                                                           if floor else ")"))
    effects = [e["name"] for e in doc.get("effects", [])]
    if effects:
        lines.append(f"the diagnosis found {', '.join(effects)}; the parameters refitted with it are kept")
    by_source: dict[str, list[str]] = {}
    for key, estimate in theta.items():
        by_source.setdefault(estimate.get("source", "measured"), []).append(key)
    for source in ("measured", "weighed", "prior"):
        if by_source.get(source):
            lines.append(f"{source}: {', '.join(by_source[source])}")
    material = doc.get("material", {})
    if material.get("source") == "unmatched":
        lines.append(f"material {material.get('text')!r} matched nothing in the library: the wide prior was used")
    elif material.get("text") and material.get("text") != material.get("name"):
        lines.append(f"material {material['text']!r} read as {material.get('name')} "
                     f"(match {material.get('match_score', 1):.2f})")
    lines += [f"FLAG: {flag_line(f)}" for f in doc.get("flags", [])]
    return lines
