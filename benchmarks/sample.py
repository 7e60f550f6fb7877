"""`twin bench sample`: build a synthetic sample and compare every figure with its truth.json.

Each build runs as its own process, so a cold run (empty Warp kernel cache and
CoACD cache) and a warm run are timed as a user would see them.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def _build(sample: Path, out: Path, method: str, cache_root: Path | None) -> float:
    env = dict(os.environ)
    args = [sys.executable, "-m", "twin.cli", "build", str(sample / "scan"), "--logs", str(sample / "trial.mcap"),
            "--holdout", str(sample / "heldout.mcap"), "-o", str(out), "--method", method]
    if cache_root is not None:
        env["WARP_CACHE_PATH"] = str(cache_root / "warp")
        env["HOME"] = str(cache_root)  # twin's CoACD cache lives under ~/.cache/twin
    t0 = time.perf_counter()
    proc = subprocess.run(args, capture_output=True, text=True, env=env)
    if proc.returncode != 0:
        raise RuntimeError(f"build of {sample} failed: {proc.stderr.strip().splitlines()[-1]}")
    return time.perf_counter() - t0


def compare(out: Path, truth_path: Path, candidate: str | None = None) -> dict:
    """Errors against a synthetic truth (world axes at placement) of the asset, or of one candidate estimate."""
    asset = json.loads((out / "asset.json").read_text())
    truth = json.loads(truth_path.read_text())
    identify = asset["provenance"]["identify"]
    theta = identify["candidates"][candidate] if candidate else {k: v["value"] for k, v in asset["theta"].items()}
    principal = np.linalg.eigvalsh(np.asarray(theta["inertia"]))
    com_world = np.add(theta["com"], asset["placement"]["position"])
    return {
        "estimate": candidate or identify["selected"],
        "mass_error_pct": 100 * (theta["mass"] / truth["mass"] - 1),
        "principal_error_pct": (100 * (principal / np.asarray(truth["principal_moments"]) - 1)).tolist(),
        "com_error_mm": float(1000 * np.linalg.norm(com_world - np.asarray(truth["com_world"]))),
        "volume_error_pct": 100 * (asset["provenance"]["decompose"]["volume_mesh_m3"] / truth["volume_m3"] - 1),
        "heldout_rmse_position_mm": 1000 * (identify["heldout_fits"][candidate]["rmse_position_m"] if candidate
                                            else asset["fit"]["final"]["rmse_position_m"]),
    }


def bench_sample(sample: Path, methods: tuple[str, ...] = ("newton", "ls")) -> list[dict]:
    """Cold and warm builds per method; prints a table and returns its rows."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for method in methods:
            for run in ("cold", "warm"):
                cache = tmp / f"cache-{method}" if run == "cold" else None
                out = tmp / f"out-{method}-{run}"
                wall = _build(sample, out, method, cache)
                rows.append({"method": method, "run": run, "wall_s": wall, **compare(out, sample / "truth.json")})
                if method == "newton" and run == "warm":
                    rows.append({"method": method, "run": "-", "wall_s": float("nan"),
                                 **compare(out, sample / "truth.json", "newton")})
    header = f"{'method':8} {'run':5} {'estimate':14} {'wall s':>7} {'mass %':>7} {'principal moments %':>24} {'COM mm':>7} " \
             f"{'volume %':>8} {'held-out mm':>11}"
    print(header)
    for r in rows:
        pm = " ".join(f"{x:+6.2f}" for x in r["principal_error_pct"])
        print(f"{r['method']:8} {r['run']:5} {r['estimate']:14} {r['wall_s']:7.1f} {r['mass_error_pct']:+7.2f} {pm:>24} "
              f"{r['com_error_mm']:7.3f} {r['volume_error_pct']:+8.2f} {r['heldout_rmse_position_mm']:11.3f}")
    return rows
