"""`twin bench paper` on MuJoCo's recordings: the smallest free case gives a row that names its engine."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.paper import _print_paper_table, engines, free_rows


def test_engine_choices_and_an_unknown_one():
    assert engines("both") == ("newton", "mujoco")
    assert engines("mujoco") == ("mujoco",)
    with pytest.raises(ValueError, match="engine"):
        engines("bullet")


def test_a_mujoco_cube_row_names_its_engine_and_has_finite_errors(capsys):
    rows = free_rows(seeds=1, duration_s=3.0, engine="mujoco", names=("cube",))
    assert [(r["object"], r["estimator"], r["engine"]) for r in rows] == [
        ("cube", estimator, "mujoco") for estimator in ("least_squares", "newton", "kept")]
    for row in rows:
        errors = [row["mass_error_pct"], *row["inertia_error_pct"], row["com_error_max_mm"]]
        assert np.all(np.isfinite(errors)), row
    capsys.readouterr()  # warp's start-up banner
    _print_paper_table(rows)
    printed = capsys.readouterr().out.splitlines()
    assert "engine" in printed[0].split()
    assert all(line.split()[2] == "mujoco" for line in printed[1:1 + len(rows)])
