"""`twin bench` runs the benchmarks of a source checkout (benchmarks/ beside the twin package); an installed
twin ships none and says so in one line."""

from pathlib import Path

import twin
from twin.cli import BENCHMARKS_MISSING, _benchmark, main


def test_bench_finds_the_checkout_beside_the_twin_package():
    module = _benchmark("priors")
    assert Path(module.__file__).resolve().parent == Path(twin.__file__).resolve().parents[1] / "benchmarks"
    assert callable(module.bench_priors)


def test_bench_of_an_installed_twin_is_one_line_and_exit_1(tmp_path, monkeypatch, capsys):
    site = tmp_path / "site-packages"
    (site / "twin").mkdir(parents=True)
    monkeypatch.setattr(twin, "__file__", str(site / "twin" / "__init__.py"))
    assert main(["bench", "priors"]) == 1
    assert capsys.readouterr().err == f"twin: error: {BENCHMARKS_MISSING}\n"
    assert BENCHMARKS_MISSING.startswith("benchmarks/: ")
