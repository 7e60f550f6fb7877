"""The readers `twin bench fuzz` and the suite's fuzz tests cover, by name."""

from __future__ import annotations

from benchmarks.fuzz_logs import LOG_TARGETS
from benchmarks.fuzz_scan import SCAN_TARGETS

TARGETS = {**SCAN_TARGETS, **LOG_TARGETS}
