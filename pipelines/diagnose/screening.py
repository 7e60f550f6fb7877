"""Screening: which candidate effects does the least-squares residual wrench ask for?

The Newton-Euler regressor plus every candidate's columns form one library.
Backward elimination under the Bayesian information criterion picks a sparse
subset of candidate groups (the inertial columns always stay), and a block
bootstrap over time repeats it to give each candidate an inclusion probability.
Rows are thinned to the low-pass filter's Nyquist rate first, so that
neighbouring rows are nearly independent and the criterion's sample count is honest.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipelines.identify import NewtonEulerRows

from .effects import CANDIDATES


@dataclass(frozen=True)
class Library:
    """Noise-scaled regression rows: X [n, base + sum k] (the base model's columns first, e.g. the 10
    inertial ones), y [n], the column range of each candidate, the sample index of each row and the
    thinning stride."""

    X: np.ndarray
    y: np.ndarray
    groups: dict[str, tuple[int, int]]
    sample: np.ndarray
    stride: int
    base: int = 10


@dataclass(frozen=True)
class Screening:
    """inclusion: bootstrap inclusion probability per candidate; selected: the subset chosen on
    all rows; coefficients: its fitted coefficients (or named parameters) per candidate; bootstraps: resamples."""

    inclusion: dict[str, float]
    selected: tuple[str, ...]
    coefficients: dict[str, list[float] | dict]
    bootstraps: int

    def leading(self, threshold: float, limit: int) -> tuple[str, ...]:
        """Candidates with inclusion at least `threshold`, most probable first, at most `limit`."""
        ranked = sorted(self.inclusion, key=lambda k: -self.inclusion[k])
        return tuple(k for k in ranked if self.inclusion[k] >= threshold)[:limit]


def build_library(rows: list[NewtonEulerRows], com_tracked: np.ndarray, names=tuple(CANDIDATES)) -> Library:
    """The library over several recordings' rows, thinned to the filter's Nyquist rate."""
    Xs, ys, samples, offset = [], [], [], 0
    stride = 1
    groups: dict[str, tuple[int, int]] = {}
    for r in rows:
        stride = max(1, int(r.rate_hz / (2 * r.cutoff_hz)))
        keep = np.arange(0, len(r.t_s), stride)
        cols = [r.A[keep]]
        start = 10
        for name in names:
            c = CANDIDATES[name].columns(r, com_tracked)[keep]
            groups[name] = (start, start + c.shape[2])
            start += c.shape[2]
            cols.append(c)
        X = np.concatenate(cols, axis=2) * r.scale[None, :, None]
        Xs.append(X.reshape(-1, X.shape[2]))
        ys.append((r.b[keep] * r.scale).reshape(-1))
        samples.append(np.repeat(keep + offset, 6))
        offset += len(r.t_s)
    return Library(np.vstack(Xs), np.concatenate(ys), groups, np.concatenate(samples), stride)


def fit_subset(lib: Library, names, rows_mask: np.ndarray | None = None) -> tuple[np.ndarray, float, int]:
    """Least squares on the base columns plus `names`' columns: (coefficients, RSS, rows)."""
    cols = list(range(lib.base)) + [c for n in names for c in range(*lib.groups[n])]
    X, y = lib.X[:, cols], lib.y
    if rows_mask is not None:
        X, y = X[rows_mask], y[rows_mask]
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ coef
    return coef, float(r @ r), len(y)


def bic(rss: float, n: int, k: int) -> float:
    return n * np.log(rss / n) + k * np.log(n)


def backward_eliminate(lib: Library, rows_mask: np.ndarray | None = None) -> tuple[str, ...]:
    """Drop candidate groups while that lowers the BIC; returns the survivors."""
    kept = list(lib.groups)

    def score(names):
        _, rss, n = fit_subset(lib, names, rows_mask)
        return bic(rss, n, lib.base + sum(lib.groups[g][1] - lib.groups[g][0] for g in names))

    current = score(kept)
    while kept:
        trials = {g: score([k for k in kept if k != g]) for g in kept}
        g = min(trials, key=trials.get)
        if trials[g] >= current:
            break
        kept.remove(g)
        current = trials[g]
    return tuple(kept)


def screen(lib: Library, rng: np.random.Generator, bootstraps: int = 40, block_samples: int = 10) -> Screening:
    """Backward elimination on all rows and on `bootstraps` block-bootstrap resamples.

    block_samples: thinned samples per bootstrap block (rows of one block are resampled together).
    """
    selected = backward_eliminate(lib)
    coef, _, _ = fit_subset(lib, selected)
    coefficients, at = {}, lib.base
    for name in selected:
        k = lib.groups[name][1] - lib.groups[name][0]
        coefficients[name] = coef[at:at + k].tolist()
        at += k

    thinned = np.unique(lib.sample)
    block_of_row = np.searchsorted(thinned, lib.sample) // block_samples
    block_count = int(block_of_row.max()) + 1
    rows_of_block = [np.flatnonzero(block_of_row == b) for b in range(block_count)]
    counts = dict.fromkeys(lib.groups, 0)
    for _ in range(bootstraps):
        pick = rng.integers(0, block_count, block_count)
        idx = np.concatenate([rows_of_block[b] for b in pick])
        boot = Library(lib.X[idx], lib.y[idx], lib.groups, lib.sample[idx], lib.stride, lib.base)
        for name in backward_eliminate(boot):
            counts[name] += 1
    return Screening({k: v / max(bootstraps, 1) for k, v in counts.items()}, selected, coefficients, bootstraps)
