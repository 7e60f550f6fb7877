"""theta0 and bounds C from geometry x material, fused with a VLM's guess as distributions.

The prior over the object's mass properties is a mixture over fills (the
material's structure: solid; printed walls t with infill f; shell walls t) and
the wall material's density rho, read from the library's (central, low, high)
as a log-normal with median `central` and low..high its 95 % range (split where
it is asymmetric). A fill is a body of moments M (geometry.py), so its mass is
rho V_M and its inertia rho J_M: the prior of log mass is a mixture of shifted
copies of the density's.

A VLM answer is a likelihood on the mass around its guess (or its density
times the volume of the fill it names), in log space a Student-t (log-normal
as its degrees of freedom grow: heavy tails so that one answer 300 % off, as
RigPI's were, cannot drag the prior far) with a spread that grows as its
stated confidence falls; where it names a fill other than the material's, that
fill joins the mixture with a weight that grows with its confidence. The
posterior is their product, evaluated on a grid of log density for every fill:

    theta0  mass = posterior median; COM and inertia = that mass times the
            posterior-weighted mean of the fills' COM and inertia per unit mass
    C       mass and each principal-axis moment Ixx, Iyy, Izz: the central
            `credible` interval of the posterior, the moments widened by
            `inertia_margin` for what no fill models (inserts, scan error);
            COM: the mesh's bounding box (any fill keeps it there)

Without a VLM answer the likelihood is flat and this is the geometry prior.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import norm

from assets import Inertial
from assets.materials import MaterialRange, find_material, material_range

from .geometry import BodyMoments, Prior, infill_moments, inner_moments, shell_moments, solid_moments
from .vlm import VlmGuess

Z95 = 1.959964


@dataclass(frozen=True)
class PriorConfig:
    """How the geometry prior is spread and how much a VLM's answer counts."""

    credible: float = 0.99
    """Probability mass of the bounds C (central interval of the posterior)."""
    infill: tuple[float, float, float] = (0.15, 0.05, 0.5)
    """Infill volume fraction of 3D prints: median, 95 % range (slicer defaults 15-20 %)."""
    wall_m: tuple[float, float, float] = (1.2e-3, 0.8e-3, 2.0e-3)
    """Wall (perimeters, top and bottom layers) of 3D prints [m]: median, 95 % range (2-5 lines of 0.4 mm)."""
    inertia_margin: float = 0.2
    """Relative widening of the inertia bounds beyond the fills' credible interval."""
    vlm_sigma: float = 0.8
    """Spread of a VLM's mass guess in log space at confidence 0.8: RigPI's VLM answers were 12-300 % off
    in mass (log errors 0.11-1.39); it grows as 1/sqrt(confidence) below that."""
    vlm_tail_dof: float = 4.0
    """Degrees of freedom of the VLM likelihood in log mass (Student-t); float('inf') makes it log-normal."""
    vlm_friction_sigma: float = 0.4
    """Spread of a VLM's friction guess in log space at confidence 0.8."""
    vlm_structure_weight: float = 0.5
    """Weight, at confidence 1, of a fill the VLM names that differs from the material's (scaled by confidence)."""
    resolution: int = 48
    """Cells of the signed-distance grid along the mesh's longest side (non-convex meshes)."""
    grid_points: int = 801
    """Points of the log-density grid."""


@dataclass(frozen=True)
class _Fill:
    label: str
    weight: float
    body: BodyMoments


def estimate_prior(mesh_object, material: MaterialRange | str | None = None, guess: VlmGuess | None = None,
                   config: PriorConfig = PriorConfig(), weighed: tuple[float, float] | None = None) -> Prior:
    """theta0 and C for a watertight mesh (object frame, metres) of `material`, fused with `guess` if given.

    weighed: (mass, standard uncertainty) [kg] from a scale. A scale beats any geometry x material
    guess, so the mass and its bounds become the weighing's; the fills and densities consistent with it
    still shape the COM and inertia. A weighed mass the material cannot explain for this volume is kept
    all the same (the library's range or the mesh may be wrong) and said in `details`.

    material: a library entry or name; None takes the VLM's material when the
    library knows it, else the wide `unknown` range. ValueError for an open mesh
    or a material the library lacks.
    """
    if isinstance(material, str):
        material = material_range(material)
    material_from = "given" if material is not None else "unknown"
    if material is None and guess is not None and guess.material:
        material = find_material(guess.material)
        material_from = "vlm" if material is not None else "unknown"
    if material is None:
        material = material_range(None)

    solid = solid_moments(mesh_object)
    volume = solid.volume
    recipes, thicknesses = _fills(material, guess, config)
    inner_method = "convex" if mesh_object.is_convex else "signed distance"
    inner = dict(zip(thicknesses, inner_moments(mesh_object, thicknesses, config.resolution))) if thicknesses else {}
    bodies = [_Fill(label, weight, _body(recipe, solid, inner)) for label, weight, recipe in recipes]
    bodies = [b for b in bodies if b.body.volume > 1e-12 * volume]

    rho = material.wall_density()
    u, q = _split_lognormal_grid(*rho, config.grid_points)
    V = np.array([b.body.volume for b in bodies])
    w = np.array([b.weight for b in bodies])
    J = np.array([np.diag(b.body.unit_inertia()) for b in bodies])  # [fill, 3] per unit density
    log_mass = u[None, :] + np.log(V)[:, None]  # [fill, grid]
    prior_w = w[:, None] * q[None, :]

    vlm_record = None
    post_w = prior_w
    if guess is not None:
        mass_v, how = _vlm_mass(guess, solid, inner, bodies, material, config)
        if mass_v is not None:
            sigma_v = config.vlm_sigma * np.sqrt(0.8 / np.clip(guess.confidence, 0.2, 1.0))
            r2 = ((log_mass - np.log(mass_v)) / sigma_v) ** 2
            nu = config.vlm_tail_dof
            post_w = prior_w * (np.exp(-0.5 * r2) if np.isinf(nu) else (1 + r2 / nu) ** (-(nu + 1) / 2))
            if post_w.sum() <= 1e-300:  # the guess lies far outside the geometry's support
                post_w = prior_w
            vlm_record = {"mass_kg": mass_v, "from": how, "sigma_log": float(sigma_v),
                          "tail_dof": None if np.isinf(nu) else float(nu)}
        vlm_record = {"answer": guess.to_json(), **(vlm_record or {"used": False})}

    weighed_record = None
    if weighed is not None:
        mass_w, std_w = weighed
        likely = post_w * np.exp(-0.5 * ((np.exp(log_mass) - mass_w) / std_w) ** 2)
        consistent = likely.sum() > 1e-12 * post_w.sum()
        post_w = likely if consistent else post_w
        weighed_record = {"mass_kg": mass_w, "std_kg": std_w, "consistent_with_material": bool(consistent)}

    lo_p, hi_p = (1 - config.credible) / 2, (1 + config.credible) / 2
    mass_samples = np.exp(log_mass).ravel()
    geometry_mass = _weighted_quantiles(mass_samples, prior_w.ravel(), (0.5, lo_p, hi_p))
    mass0, mass_lo, mass_hi = _weighted_quantiles(mass_samples, post_w.ravel(), (0.5, lo_p, hi_p))
    if weighed is not None:
        z = float(norm.ppf(hi_p))
        mass0, mass_lo, mass_hi = weighed[0], max(weighed[0] - z * weighed[1], 1e-9), weighed[0] + z * weighed[1]
    fill_w = post_w.sum(axis=1) / post_w.sum()
    com0 = sum(fw * b.body.com for fw, b in zip(fill_w, bodies))
    per_mass = sum(fw * b.body.unit_inertia() / b.body.volume for fw, b in zip(fill_w, bodies))
    inertial = Inertial(mass0, tuple(com0), mass0 * per_mass)
    rho_grid = np.exp(u)
    inertia_lo, inertia_hi = [], []
    for k in range(3):
        if weighed_record is not None and not weighed_record["consistent_with_material"]:
            # the scale, not the material's density, sets the mass: each fill's moment per kilogram times its bounds
            per_kg = J[:, k] / V
            a, b = per_kg.min() * mass_lo, per_kg.max() * mass_hi
        else:
            values = (J[:, k][:, None] * rho_grid[None, :]).ravel()
            a, b = _weighted_quantiles(values, post_w.ravel(), (lo_p, hi_p))
        inertia_lo.append(a * (1 - config.inertia_margin))
        inertia_hi.append(b * (1 + config.inertia_margin))
    box_lo, box_hi = np.asarray(mesh_object.bounds, dtype=float)
    lower = (mass_lo, *box_lo, *inertia_lo)
    upper = (mass_hi, *box_hi, *inertia_hi)

    uniform = solid.inertial(mass0 / volume)
    labels = {}
    for fw, b in zip(fill_w, bodies):
        labels[b.label] = labels.get(b.label, 0.0) + float(fw)
    structure = "+".join(k for k, v in sorted(labels.items(), key=lambda kv: -kv[1]) if v >= 0.01)
    friction = _fuse_friction((material.friction, material.friction_low, material.friction_high),
                              guess.friction_static if guess else None, guess, config)
    friction_kinetic = _fuse_friction(material.kinetic(), guess.friction_kinetic if guess else None, guess, config)
    details = {"fusion": {
        "material_from": material_from,
        "wall_density_kg_m3": list(rho),
        "credible": config.credible,
        "inertia_margin": config.inertia_margin,
        "fill_weights": labels,
        "inner_offset": inner_method if thicknesses else None,
        "geometry": {"mass_kg": geometry_mass[0], "mass_interval_kg": list(geometry_mass[1:])},
        "vlm": vlm_record,
        "weighed": weighed_record,
        "fused": {"mass_kg": mass0, "mass_interval_kg": [mass_lo, mass_hi]},
    }}
    return Prior(inertial, tuple(map(float, lower)), tuple(map(float, upper)), material, volume, uniform,
                 friction=friction, friction_kinetic=friction_kinetic, structure=structure, details=details)


def _fills(material: MaterialRange, guess: VlmGuess | None, config: PriorConfig):
    """The mixture of fills as (label, weight, recipe) plus the wall thicknesses [m] their inner bodies need.

    A recipe is ("solid",), ("shell", t) or ("printed", t, f); weights sum to 1.
    """
    own = _structure_fills(material.structure, material.wall_m or config.wall_m, config.infill)
    fills = [(label, w, recipe) for label, w, recipe in own]
    if guess is not None and guess.structure is not None:
        structure = {"hollow": "shell"}.get(guess.structure, guess.structure)
        wall = guess.wall_thickness_m
        named = structure != material.structure or wall is not None or guess.infill_fraction is not None
        if named:
            a = config.vlm_structure_weight * float(np.clip(guess.confidence, 0.0, 1.0))
            wall_range = (wall, wall / 2, wall * 2) if wall else (material.wall_m or config.wall_m)
            infill = guess.infill_fraction
            infill_range = (infill, infill / 3, min(1.0, infill * 3)) if infill else config.infill
            theirs = _structure_fills(structure, wall_range, infill_range)
            fills = [(lb, w * (1 - a), r) for lb, w, r in fills] + [(lb, w * a, r) for lb, w, r in theirs]
    thicknesses = sorted({r[1] for _, _, r in fills if r[0] != "solid"})
    return [(lb, w, r) for lb, w, r in fills if w > 0], thicknesses


def _structure_fills(structure: str, wall_m, infill) -> list:
    if structure == "solid":
        return [("solid", 1.0, ("solid",))]
    t_nodes, t_w = _lognormal_nodes(*wall_m, count=7, z_max=3.0)
    if structure == "shell":
        return [("shell", w, ("shell", t)) for t, w in zip(t_nodes, t_w)]
    f_nodes, f_w = _lognormal_nodes(*infill, count=41, z_max=3.5)
    f_nodes = np.minimum(f_nodes, 1.0)
    return [("printed", tw * fw, ("printed", t, f)) for t, tw in zip(t_nodes, t_w) for f, fw in zip(f_nodes, f_w)]


def _body(recipe, solid: BodyMoments, inner: dict) -> BodyMoments:
    if recipe[0] == "solid":
        return solid
    if recipe[0] == "shell":
        return shell_moments(solid, inner[recipe[1]])
    return infill_moments(solid, inner[recipe[1]], float(recipe[2]))


def _lognormal_nodes(median: float, low: float, high: float, count: int, z_max: float):
    """Nodes and weights (summing to 1) of a split log-normal with median `median` and 95 % range low..high."""
    z = np.linspace(-z_max, z_max, count)
    s_lo, s_hi = np.log(median / low) / Z95, np.log(high / median) / Z95
    nodes = median * np.exp(np.where(z < 0, s_lo, s_hi) * z)
    w = np.exp(-0.5 * z**2)  # u = median + sigma_side z with z standard normal: low..high is exactly 95 %
    return nodes, w / w.sum()


def _split_lognormal_grid(central: float, low: float, high: float, points: int):
    """Log-density grid u [ln(kg/m^3)] and probability weights (summing to 1) of the split log-normal."""
    s_lo = max(np.log(central / low) / Z95, 1e-3)
    s_hi = max(np.log(high / central) / Z95, 1e-3)
    z = np.linspace(-5.0, 5.0, points)
    sigma = np.where(z < 0, s_lo, s_hi)
    u = np.log(central) + sigma * z
    q = np.exp(-0.5 * z**2)  # equal steps of the standard normal z: the median stays at `central`
    return u, q / q.sum()


def _weighted_quantiles(values: np.ndarray, weights: np.ndarray, probs) -> tuple[float, ...]:
    order = np.argsort(values)
    v, w = values[order], weights[order]
    cdf = np.cumsum(w)
    cdf = cdf / cdf[-1]
    return tuple(float(np.interp(p, cdf, v)) for p in probs)


def _vlm_mass(guess: VlmGuess, solid, inner, bodies, material, config) -> tuple[float | None, str]:
    """The VLM's mass [kg]: its own mass guess, else its density times the volume of the fill it names."""
    if guess.mass_kg is not None:
        return guess.mass_kg, "mass"
    if guess.density_kg_m3 is None:
        return None, "none"
    structure = {"hollow": "shell"}.get(guess.structure or "", guess.structure)
    volume = solid.volume
    wall = guess.wall_thickness_m
    if structure in ("shell", "printed"):
        # the fill the VLM names; its inner body was computed for the mixture (same thickness)
        t = wall if wall is not None else (material.wall_m or config.wall_m)[0]
        same = [b.body for b in bodies if b.label == structure]
        if wall is not None and t in inner:
            f = 0.0 if structure == "shell" else (guess.infill_fraction or config.infill[0])
            volume = infill_moments(solid, inner[t], min(f, 1.0)).volume
        elif same:
            volume = float(np.median([b.volume for b in same]))
    return guess.density_kg_m3 * volume, "density x fill volume"


def _fuse_friction(library: tuple[float, float, float], guessed: float | None, guess: VlmGuess | None,
                   config: PriorConfig) -> tuple[float, float, float]:
    """Library friction (value, low, high) fused with a VLM's guess as log-normals; the library's alone without."""
    c, lo, hi = (float(x) for x in library)
    if guessed is None or guess is None:
        return (c, lo, hi)
    s_lib = max(np.log(hi / lo) / (2 * Z95), 1e-3)
    s_vlm = config.vlm_friction_sigma * np.sqrt(0.8 / np.clip(guess.confidence, 0.2, 1.0))
    prec = 1 / s_lib**2 + 1 / s_vlm**2
    mu = (np.log(c) / s_lib**2 + np.log(guessed) / s_vlm**2) / prec
    s = 1 / np.sqrt(prec)
    return (float(np.exp(mu)), float(np.exp(mu - Z95 * s)), float(np.exp(mu + Z95 * s)))
