"""`twin diagnose`: bad input is one clear line and exit code 1."""

from __future__ import annotations

from twin.cli import main


def test_diagnose_without_build_output_names_the_file(tmp_path, capsys):
    """Diagnosing a directory that `twin build` never wrote fails naming its asset.json."""
    code = main(["diagnose", str(tmp_path / "nothing"), "--logs", str(tmp_path / "trial.mcap")])
    assert code == 1
    err = capsys.readouterr().err
    assert "twin: error:" in err and "nothing/asset.json: not found" in err
