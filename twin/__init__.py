"""Command line, orchestration and reports."""
