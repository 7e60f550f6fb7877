"""`twin bench fuzz`: every reader fed seeded mutations of a valid input; outcomes counted per reader.

A reader passes when each mutated input is either read or rejected with one of the project's own
errors (whose message names the file); anything else is an uncaught exception, printed with the
seed that reproduces it. The mutations are byte-level (bit flips, cut, spliced and duplicated spans,
truncation) and, for JSON, structural (a value replaced by another type, a huge or non-finite number,
a key dropped), so that both the parser and the checks behind it are reached.
"""

from __future__ import annotations

import copy
import json
import shutil
import tempfile
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

ODD_VALUES = (None, True, 0, -1, 5, 1e308, -1e308, 10**400, "", "x", "nan", [], [[]], {}, {"a": 1}, [1.0] * 3,
              float("nan"), float("inf"), "../../etc/passwd", 2**63, -(2**31))
"""What a JSON value is swapped for: wrong types, empties, huge and non-finite numbers, odd paths."""


@dataclass(frozen=True)
class FuzzTarget:
    """One reader under fuzzing.

    make_seed: writes a valid input under the given folder and returns the path handed to `read`.
    mutate: changes that input in place (every file it consists of is fair game).
    read: the reader; its return value is ignored.
    errors: the project's error types it may raise.
    """

    name: str
    make_seed: Callable[[Path], Path]
    mutate: Callable[[Path, np.random.Generator], None]
    read: Callable[[Path], object]
    errors: tuple[type[BaseException], ...]


@dataclass
class FuzzResult:
    name: str
    outcomes: Counter = field(default_factory=Counter)
    uncaught: list[tuple[int, str]] = field(default_factory=list)
    """(iteration, 'Type: message') of each uncaught exception; the iteration reproduces it."""


def mutate_bytes(path: Path, rng: np.random.Generator) -> None:
    """One to three byte-level edits of a file."""
    data = bytearray(path.read_bytes())
    for _ in range(int(rng.integers(1, 4))):
        n = len(data)
        op = int(rng.integers(0, 6))
        if n == 0:
            data += bytes(rng.integers(0, 256, 8, dtype=np.uint8))
            continue
        i = int(rng.integers(0, n))
        span = int(rng.integers(1, max(2, min(64, n - i) + 1)))
        if op == 0:  # bit flips
            for j in rng.integers(0, n, int(rng.integers(1, 9))):
                data[j] ^= 1 << int(rng.integers(0, 8))
        elif op == 1:  # cut a span
            del data[i:i + span]
        elif op == 2:  # insert random bytes
            data[i:i] = bytes(rng.integers(0, 256, span, dtype=np.uint8))
        elif op == 3:  # duplicate a span
            data[i:i] = data[i:i + span]
        elif op == 4:  # truncate
            del data[i:]
        else:  # an interesting byte run (0x00, 0xff, 0x7f...)
            data[i:i + span] = bytes([int(rng.choice([0, 0x7F, 0x80, 0xFF]))]) * span
    path.write_bytes(bytes(data))


def _nodes(doc, trail=()):
    """(container, key) of every value in a JSON document."""
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield doc, k
            yield from _nodes(v, trail + (k,))
    elif isinstance(doc, list):
        for k, v in enumerate(doc):
            yield doc, k
            yield from _nodes(v, trail + (k,))


def mutate_json_doc(doc, rng: np.random.Generator):
    """The document with one to three structural edits; the document itself may be replaced."""
    for _ in range(int(rng.integers(1, 4))):
        nodes = list(_nodes(doc))
        if not nodes or rng.random() < 0.05:
            return copy.deepcopy(ODD_VALUES[int(rng.integers(0, len(ODD_VALUES)))])
        container, key = nodes[int(rng.integers(0, len(nodes)))]
        op = rng.random()
        if op < 0.2 and isinstance(container, dict):
            del container[key]
        elif op < 0.3 and isinstance(container[key], (int, float)) and not isinstance(container[key], bool):
            container[key] = container[key] * float(rng.choice([-1.0, 0.0, 1e-12, 1e6, 1e300]))
        elif op < 0.4 and isinstance(container[key], list) and container[key]:
            container[key] = container[key][: int(rng.integers(0, len(container[key])))]
        else:
            container[key] = copy.deepcopy(ODD_VALUES[int(rng.integers(0, len(ODD_VALUES)))])
    return doc


def mutate_json(path: Path, rng: np.random.Generator) -> None:
    """A structural edit of a JSON file (three times in four), else a byte-level one."""
    if rng.random() < 0.25:
        mutate_bytes(path, rng)
        return
    try:
        doc = json.loads(path.read_text())
    except (ValueError, UnicodeDecodeError):
        mutate_bytes(path, rng)
        return
    text = json.dumps(mutate_json_doc(doc, rng), allow_nan=True)
    path.write_text(text)


def run_fuzz(target: FuzzTarget, count: int, seed: int = 0) -> FuzzResult:
    """`count` mutations of the target's seed input, each in a fresh copy."""
    result = FuzzResult(target.name)
    with tempfile.TemporaryDirectory(prefix="twin-fuzz-") as root:
        pristine = Path(root) / "seed"
        pristine.mkdir()
        seed_path = target.make_seed(pristine)
        for i in range(count):
            rng = np.random.default_rng([seed, i])
            work = Path(root) / "work"
            shutil.rmtree(work, ignore_errors=True)
            shutil.copytree(pristine, work)
            path = work / seed_path.relative_to(pristine)
            target.mutate(path, rng)
            try:
                target.read(path)
                result.outcomes["read"] += 1
            except target.errors as exc:
                result.outcomes[f"rejected: {type(exc).__name__}"] += 1
            except (Exception, RecursionError) as exc:  # noqa: BLE001 - what the bench exists to count
                result.outcomes[f"uncaught: {type(exc).__name__}"] += 1
                result.uncaught.append((i, f"{type(exc).__name__}: {str(exc)[:200]}"))
    return result


def fuzz_targets() -> dict[str, FuzzTarget]:
    """Every reader the bench covers, by name."""
    from benchmarks import fuzz_targets as targets

    return targets.TARGETS


EARLY_ERRORS = {
    "SOURCE missing": ["build", "{tmp}/nowhere", "--logs", "{sample}/trial.mcap", "-o", "{tmp}/out"],
    "OUT an existing file": ["build", "{sample}/scan", "--logs", "{sample}/trial.mcap", "-o", "{tmp}/file.txt"],
    "OUT unwritable": ["build", "{sample}/scan", "--logs", "{sample}/trial.mcap", "-o", "/proc/twin-out"],
    "material unknown": ["build", "{sample}/scan", "--logs", "{sample}/trial.mcap", "-o", "{tmp}/out",
                         "--material", "unobtainium"],
    "topic absent": ["build", "{sample}/scan", "--logs", "{sample}/trial.mcap", "-o", "{tmp}/out",
                     "--topic", "wrench=/netft_data"],
}
"""Mistakes a user should hear about within two seconds of pressing enter."""


def time_to_error(sample: Path) -> list[tuple[str, float, int, str]]:
    """(case, seconds from start to exit, exit code, the error line) of `twin` run as a user runs it."""
    import subprocess
    import sys
    import time

    rows = []
    with tempfile.TemporaryDirectory(prefix="twin-errors-") as tmp:
        (Path(tmp) / "file.txt").write_text("a user's file")
        for case, argv in EARLY_ERRORS.items():
            args = [a.format(tmp=tmp, sample=sample) for a in argv]
            t0 = time.perf_counter()
            done = subprocess.run([sys.executable, "-m", "twin.cli", *args], capture_output=True, text=True)
            rows.append((case, time.perf_counter() - t0, done.returncode, done.stderr.strip().splitlines()[-1:]))
    return rows


def bench_fuzz(count: int = 2000, names: tuple[str, ...] = (), seed: int = 0,
               sample: Path = Path("samples/cube")) -> None:
    targets = fuzz_targets()
    chosen = names or tuple(targets)
    unknown = [n for n in chosen if n not in targets]
    if unknown:
        raise ValueError(f"unknown fuzz target(s) {unknown}; choose from {', '.join(targets)}")
    print(f"{'wrong input':<22} {'error after':>11}  exit  line")
    for case, seconds, code, line in time_to_error(sample):
        print(f"{case:<22} {seconds:>9.2f} s  {code:>4}  {line[0] if line else ''}", flush=True)
    print()
    print(f"{'reader':<22} {'inputs':>7}  outcomes")
    for name in chosen:
        result = run_fuzz(targets[name], count, seed)
        outcomes = ", ".join(f"{k} {v}" for k, v in sorted(result.outcomes.items()))
        print(f"{name:<22} {count:>7}  {outcomes}", flush=True)
        for i, what in result.uncaught[:5]:
            print(f"    iteration {i}: {what}")
