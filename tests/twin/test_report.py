"""The build report's sections from asset.json as a build writes it."""

from twin.report import diagnosis_section


def test_a_skipped_diagnosis_is_reported_as_skipped_not_a_crash():
    """A build whose diagnosis could not run (e.g. trial halves too short) keeps its asset; the report says why."""
    asset = {"provenance": {"diagnose": {"skipped": "trial halves too short for one 0.6 s window each"}}}
    html = diagnosis_section(asset, None)
    assert "Skipped" in html and "too short" in html
