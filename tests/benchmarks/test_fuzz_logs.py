"""Bounded fuzzing of the recording readers and asset.json: every mutated input is read or rejected with the
project's own error, its message '<file>: <problem>' on one line (`twin bench fuzz` runs them longer)."""

from __future__ import annotations

import pytest

from benchmarks.fuzz import run_fuzz
from benchmarks.fuzz_logs import LOG_TARGETS

INPUTS = 500
"""Per reader: about a second each, the MCAP reader three."""


@pytest.mark.parametrize("name", ["mcap", "push-json", "push-h5", "asset-json"])
def test_reader_raises_nothing_but_its_own_errors(name):
    """Some inputs still read, most are refused, none escapes as another exception."""
    result = run_fuzz(LOG_TARGETS[name], INPUTS)
    assert result.uncaught == []
    assert result.outcomes["read"] > 0
    assert sum(n for outcome, n in result.outcomes.items() if outcome.startswith("rejected")) > INPUTS // 2
