"""Fuzzing the object-source readers: every mutated input reads or raises the project's error, on one line.

`twin bench fuzz` runs thousands of inputs per reader; these tests run a few hundred each so that a
regression shows up in the suite. A failure prints the iterations that reproduce it
(`run_fuzz(target, i + 1)` replays iteration i).
"""

from __future__ import annotations

import dataclasses
import re

import pytest

from benchmarks.fuzz import run_fuzz
from benchmarks.fuzz_scan import SCAN_TARGETS

COUNTS = {"scan-nerfstudio": 300, "scan-pose-free": 200, "scan-7scenes": 300, "mesh": 400}


def _checking_messages(target):
    """The target with its read also failing on a message that is not `<file>: <problem>` on one line."""

    def read(path):
        try:
            target.read(path)
        except target.errors as e:
            message = str(e)
            if "\n" in message or not re.match(r"^/\S*: \S", message) or len(message) > 600:
                raise AssertionError(f"badly formed message: {message[:300]!r}") from e
            raise

    return dataclasses.replace(target, read=read)


@pytest.mark.parametrize("name", sorted(COUNTS))
def test_mutated_inputs_read_or_raise_the_project_error(name):
    result = run_fuzz(_checking_messages(SCAN_TARGETS[name]), COUNTS[name])
    repro = "\n".join(f"  iteration {i}: {what}" for i, what in result.uncaught[:10])
    assert not result.uncaught, f"{name}: {len(result.uncaught)} uncaught of {COUNTS[name]}:\n{repro}"
    assert result.outcomes["read"] > 0, f"{name}: no mutated input read at all: {dict(result.outcomes)}"
