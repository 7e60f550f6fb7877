"""Residual analysis of the wrench a model leaves unexplained, per channel and over time.

The residual is measured minus predicted wrench in tracked-frame axes about
the tracked origin, divided by each channel's noise level (so 1 is the sensor's
noise). Per channel: RMS, whiteness (Ljung-Box over the thinned residual),
the lag of the peak cross-correlation with the measured wrench (a peak away
from zero lag points to a delay), and correlations with position, velocity,
sign of velocity, speed squared and the gravity direction in the body frame.
Over time: stretches where the residual stands out, in words and numbers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import uniform_filter1d
from scipy.stats import chi2

from pipelines.identify import NewtonEulerRows

CHANNELS = ("fx", "fy", "fz", "tx", "ty", "tz")
PLANAR_CHANNELS = ("x", "y", "heading")


@dataclass(frozen=True)
class ResidualAnalysis:
    """Per channel (the wrench's six, a joint's effort, or a pushed object's x, y, heading replay errors):
    rms in noise units; whiteness_p: Ljung-Box p-values (small: not white);
    xcorr_peak_lag_s and xcorr_peak: residual vs the measured wrench (pusher force) of the same channel;
    correlation: feature -> Pearson coefficient per channel (velocity-like features use the linear
    velocity for force channels and the angular velocity for torque channels); localisation:
    {"summary", "where": {"t_s": [a, b], "speed": [a, b]}, "share"} per stretch, largest first;
    channels: the residual's channel names."""

    rms: list[float]
    whiteness_p: list[float]
    xcorr_peak_lag_s: list[float]
    xcorr_peak: list[float]
    correlation: dict[str, list[float]]
    localisation: list[dict]
    channels: tuple[str, ...] = CHANNELS

    def to_json(self) -> dict:
        return {"channels": list(self.channels), "rms_noise_units": self.rms, "whiteness_p": self.whiteness_p,
                "xcorr_peak_lag_s": self.xcorr_peak_lag_s, "xcorr_peak": self.xcorr_peak,
                "correlation": self.correlation, "localisation": self.localisation}


def _pearson(a: np.ndarray, b: np.ndarray) -> float:
    a, b = a - a.mean(), b - b.mean()
    d = np.sqrt((a @ a) * (b @ b))
    return float(a @ b / d) if d > 0 else 0.0


def _ljung_box_p(x: np.ndarray, lags: int) -> float:
    x = x - x.mean()
    n = len(x)
    denom = x @ x
    if denom <= 0 or n <= lags + 1:
        return 1.0
    rho = np.array([x[:-k] @ x[k:] / denom for k in range(1, lags + 1)])
    q = n * (n + 2) * np.sum(rho**2 / (n - np.arange(1, lags + 1)))
    return float(chi2.sf(q, lags))


def _peak_lag(residual: np.ndarray, signal: np.ndarray, max_lag: int) -> tuple[int, float]:
    r, s = residual - residual.mean(), signal - signal.mean()
    norm = np.sqrt((r @ r) * (s @ s))
    if norm <= 0:
        return 0, 0.0
    best, peak = 0, 0.0
    for lag in range(-max_lag, max_lag + 1):
        c = (r[max(lag, 0):len(r) + min(lag, 0)] @ s[max(-lag, 0):len(s) - max(lag, 0)]) / norm
        if abs(c) > abs(peak):
            best, peak = lag, c
    return best, float(peak)


def analyse_residuals(rows: NewtonEulerRows, residual: np.ndarray, *, stride: int, max_lag_s: float = 0.05,
                      block_s: float = 0.25, excess: float = 4.0) -> ResidualAnalysis:
    """Analyse `residual` [N, 6] (noise units) of `rows`; `stride` thins to nearly independent samples.

    A stretch is localised where the residual energy, averaged over `block_s`,
    exceeds `excess` times its median.
    """
    thin = residual[::stride]
    speed = np.linalg.norm(rows.velocity, axis=1)
    motion = np.concatenate([rows.velocity, rows.omega], axis=1)
    displacement = rows.position - rows.position[0]
    features = {
        "position": np.concatenate([displacement, displacement], axis=1),
        "velocity": motion,
        "sign_velocity": np.sign(motion),
        "speed_squared": np.concatenate([np.abs(rows.velocity) * rows.velocity,
                                         np.abs(rows.omega) * rows.omega], axis=1),
        "gravity": np.concatenate([rows.gravity, rows.gravity], axis=1),
    }
    max_lag = int(round(max_lag_s * rows.rate_hz))
    lags = [_peak_lag(residual[:, j], rows.b[:, j], max_lag) for j in range(6)]
    return ResidualAnalysis(
        rms=np.sqrt(np.mean(residual**2, axis=0)).tolist(),
        whiteness_p=[_ljung_box_p(thin[:, j], 10) for j in range(6)],
        xcorr_peak_lag_s=[lag / rows.rate_hz for lag, _ in lags],
        xcorr_peak=[p for _, p in lags],
        correlation={k: [_pearson(residual[:, j], f[:, j]) for j in range(6)] for k, f in features.items()},
        localisation=_localise(rows.t_s, residual, int(block_s * rows.rate_hz), speed, excess),
    )


def analyse_joint_residual(t_s: np.ndarray, q: np.ndarray, qd: np.ndarray, effort: np.ndarray,
                           residual: np.ndarray, *, stride: int, unit: str, max_lag_s: float = 0.05,
                           block_s: float = 0.25, excess: float = 4.0) -> ResidualAnalysis:
    """Analyse a joint's effort residual [N] (noise units) against q, qd [m or rad, /s] and the effort;
    `unit` names the speed's unit ("m/s" or "rad/s") in the localisation."""
    rate_hz = 1.0 / float(np.median(np.diff(t_s)))
    features = {"position": q - q[0], "velocity": qd, "sign_velocity": np.sign(qd), "speed_squared": np.abs(qd) * qd}
    lag, peak = _peak_lag(residual, effort, int(round(max_lag_s * rate_hz)))
    return ResidualAnalysis(
        rms=[float(np.sqrt(np.mean(residual**2)))],
        whiteness_p=[_ljung_box_p(residual[::stride], 10)],
        xcorr_peak_lag_s=[lag / rate_hz], xcorr_peak=[peak],
        correlation={k: [_pearson(residual, f)] for k, f in features.items()},
        localisation=_localise(t_s, residual[:, None], int(block_s * rate_hz), np.abs(qd), excess,
                               speed_name="|qdot|", speed_unit=unit,
                               what="joint effort residual"),
        channels=("effort",),
    )


def analyse_planar_residual(t_s: np.ndarray, velocity: np.ndarray, force: np.ndarray, residual: np.ndarray, *,
                            window_samples: int, recordings: np.ndarray | None = None, block_s: float = 0.25,
                            excess: float = 4.0) -> ResidualAnalysis:
    """Analyse a pushed object's replay errors [N, 3] (x, y, heading arc; tracker-noise units), window by window.

    Rows run through windows of `window_samples` samples, each replayed from a measured start; velocity [N, 3]:
    vx, vy [m/s], yaw rate [rad/s]; force [N, 2]: the pusher's, world x, y [N]. The error accumulates within a
    window, so whiteness is tested on the windows' final errors, and correlations and the cross-correlation
    with the force on its per-sample increments (what each step adds: force and state errors act there).
    recordings: per row, the recording's name (t_s is each recording's own time).
    """
    S = window_samples
    increments = np.diff(np.concatenate([np.zeros((len(residual) // S, 1, 3)), residual.reshape(-1, S, 3)], 1),
                         axis=1).reshape(-1, 3)
    magnitude = np.linalg.norm(force, axis=1)
    pushing = np.c_[force, magnitude]  # the heading channel against the force's size
    features = {"velocity": velocity, "sign_velocity": np.sign(velocity), "speed_squared": np.abs(velocity) * velocity,
                "force": pushing}
    rate_hz = 1.0 / float(np.median(np.diff(t_s[:S]))) if S > 1 else 1.0
    lags = [_peak_lag(increments[:, j], pushing[:, j], max(1, S // 3)) for j in range(3)]
    final = residual[S - 1::S]
    return ResidualAnalysis(
        rms=np.sqrt(np.mean(residual**2, axis=0)).tolist(),
        whiteness_p=[_ljung_box_p(final[:, j], max(1, min(10, len(final) // 4))) for j in range(3)],
        xcorr_peak_lag_s=[lag / rate_hz for lag, _ in lags],
        xcorr_peak=[p for _, p in lags],
        correlation={k: [_pearson(increments[:, j], f[:, j]) for j in range(3)] for k, f in features.items()},
        localisation=_localise(t_s, residual, int(block_s * rate_hz), np.linalg.norm(velocity[:, :2], axis=1),
                               excess, what="replay error", recordings=recordings),
        channels=PLANAR_CHANNELS,
    )


def _hot_runs(energy: np.ndarray, excess: float, breaks: np.ndarray | None = None) -> np.ndarray:
    """Per sample, the number (from 1) of the run of samples where `energy` exceeds `excess` x its median, or 0;
    `breaks` (bool per sample) starts a new run."""
    hot = energy > excess * np.median(energy)
    start = hot & np.r_[True, ~hot[:-1]]
    if breaks is not None:
        start |= hot & breaks
    return np.where(hot, np.cumsum(start), 0)


def _largest_share_by_chance(residual: np.ndarray, block: int, excess: float, share: float, surrogates: int = 1000,
                             enough: int = 20, seed: int = 0) -> np.ndarray:
    """The largest share of the residual energy that one stretch holds (as `_localise` finds them) in each of up
    to `surrogates` series with the residual's [N, channels] spectrum and random phases (the same for every
    channel, so that their cross-spectra stay): what noise as coloured as this residual puts in one stretch
    somewhere in the recording. It stops once `enough` of them reach `share` (Besag and Clifford's sequential
    test: a stretch that noise matches that often is settled; a minute of clean one-channel residual at 1 kHz
    took 41-1000 series, 0.3-5 s). A low-passed residual rings near its cutoff, and ringing noise has few
    independent samples in a short stretch: on a clean Newton-made cabinet door, a reversal held 23 % of the
    residual at 5x its typical energy, as such noise does in about one recording in 80."""
    rng = np.random.default_rng(seed)
    spectrum = np.fft.rfft(residual, axis=0)  # its mean kept (phase 0), so that its energy is the residual's
    out = np.zeros(surrogates)
    for k in range(surrogates):
        phase = np.exp(2j * np.pi * rng.random(len(spectrum)))
        phase[0] = 1.0
        raw = np.sum(np.fft.irfft(spectrum * phase[:, None], n=len(residual), axis=0) ** 2, axis=1)
        runs = _hot_runs(uniform_filter1d(raw, block), excess)
        if runs.any():
            out[k] = np.bincount(runs, raw)[1:].max() / raw.sum()
        if out[k] >= share and np.sum(out[:k + 1] >= share) >= enough:
            return out[:k + 1]
    return out


def _localise(t: np.ndarray, residual: np.ndarray, block: int, speed: np.ndarray, excess: float,
              speed_name: str = "|v|", speed_unit: str = "m/s", what: str = "wrench residual",
              recordings: np.ndarray | None = None) -> list[dict]:
    """Stretches where the residual [N, channels] energy, averaged over `block` samples, exceeds `excess` x its
    median, largest share first, each with the chance ("p_value") that noise with the residual's spectrum puts
    as large a share in one stretch somewhere (`_largest_share_by_chance`).

    recordings: per sample, the name of the recording it comes from (several evaluation recordings run one
    after another, each with its own clock): a stretch ends where the recording does, and says which it is.
    """
    raw = np.sum(residual**2, axis=1)
    energy = uniform_filter1d(raw, max(1, block))
    runs = _hot_runs(energy, excess, None if recordings is None else np.r_[False, recordings[1:] != recordings[:-1]])
    total = raw.sum()
    shares = np.bincount(runs, raw)[1:] / total if total > 0 else np.zeros(runs.max())
    by_chance = (_largest_share_by_chance(residual, max(1, block), excess, float(shares.max())) if runs.any()
                 else np.zeros(0))
    out = []
    for run in range(1, runs.max() + 1):
        a, b = (int(i) for i in np.flatnonzero(runs == run)[[0, -1]] + (0, 1))
        share = float(shares[run - 1])
        chance = float((1 + np.sum(by_chance >= share)) / (1 + len(by_chance)))
        lo, hi = float(speed[a:b].min()), float(speed[a:b].max())
        ratio = float(np.sqrt(energy[a:b].max() / max(np.median(energy), 1e-30)))
        where = {"t_s": [float(t[a]), float(t[b - 1])], "speed": [lo, hi]}
        source = ""
        if recordings is not None:
            where["recording"] = str(recordings[a])
            source = f" of {recordings[a]}"
        out.append({
            "summary": f"{what} up to {ratio:.1f}x its typical size at t = {t[a]:.2f}-{t[b - 1]:.2f} s{source}, "
                       f"{speed_name} = {lo:.2f}-{hi:.2f} {speed_unit} ({100 * share:.0f} % of the residual; "
                       f"noise of its spectrum holds as much in one stretch with p = {chance:.3f})",
            "where": where,
            "share": share,
            "p_value": chance,
        })
    return sorted(out, key=lambda d: -d["share"])


def unexplained(analysis: ResidualAnalysis, min_share: float, max_chance: float,
                span_s: tuple[float, float] | None = None, residual: np.ndarray | None = None,
                p_value: float = 1e-6) -> tuple[dict, ...]:
    """DESIGN.md `unexplained` entries for what a chosen model leaves: when some channel is not white (Ljung-Box
    p below `p_value`), the stretches holding at least `min_share` of the residual that noise of the residual's
    own spectrum puts in one stretch less often than `max_chance` (`_localise`).

    With `span_s` (the evaluation's time span [s]) and `residual` [N, channels], a non-white residual in which no
    stretch stands out (a mismatch spread over everything) is reported per non-white channel over that span,
    with the channel's share of the residual.
    """
    if min(analysis.whiteness_p) >= p_value:
        return ()
    stretches = tuple({"summary": s["summary"], "where": s["where"], "share": s["share"]}
                      for s in analysis.localisation if s["share"] >= min_share and s["p_value"] < max_chance)
    if stretches or span_s is None or residual is None:
        return stretches
    energy = np.sum(residual**2, axis=0)
    return tuple(
        {"summary": f"{ch} residual not white (Ljung-Box p = {p:.1e}), RMS {rms:.0f}x noise, spread over the "
                    "whole evaluation",
         "where": {"t_s": [float(span_s[0]), float(span_s[1])]}, "share": float(energy[j] / energy.sum())}
        for j, (ch, p, rms) in enumerate(zip(analysis.channels, analysis.whiteness_p, analysis.rms)) if p < p_value)


def describe(analysis: ResidualAnalysis, threshold: float = 0.3) -> list[str]:
    """The analysis in words: non-white channels, delay-like lags, strong state correlations."""
    lines = []
    for j, ch in enumerate(analysis.channels):
        if analysis.whiteness_p[j] < 1e-3:
            lines.append(f"{ch}: residual not white (Ljung-Box p = {analysis.whiteness_p[j]:.1e}), "
                         f"RMS {analysis.rms[j]:.2f}x noise")
        if analysis.xcorr_peak_lag_s[j] != 0 and abs(analysis.xcorr_peak[j]) > threshold:
            against = "wrench" if ch in CHANNELS else ("pusher force" if ch in PLANAR_CHANNELS else ch)
            lines.append(f"{ch}: residual peaks against the measured {against} at lag "
                         f"{1000 * analysis.xcorr_peak_lag_s[j]:+.0f} ms (r = {analysis.xcorr_peak[j]:.2f})")
        for k, values in analysis.correlation.items():
            if abs(values[j]) > threshold:
                lines.append(f"{ch}: residual correlates with {k.replace('_', ' ')} (r = {values[j]:+.2f})")
    lines += [s["summary"] for s in analysis.localisation[:3]]
    return lines


def localise_joint_friction(q: np.ndarray, qd: np.ndarray, residual: np.ndarray, *, stride: int, unit: str,
                            q_unit: str, bins: int = 10, z: float = 4.0, min_speed_share: float = 0.05,
                            ) -> tuple[dict, ...]:
    """Where in the joint's state a friction-like mismatch lies: the effort residual [noise units] times the
    direction of motion, r sign(q'), is what a friction the model lacks leaves (positive: more friction than
    modelled, the robot pushes harder along the motion). Its mean is tested per q bin (a binding stretch of
    the travel) and per direction of motion (a runner that catches one way); thinned rows (`stride`) are
    taken as independent for the standard errors.

    Returns DESIGN.md `unexplained` entries: {"summary", "where": {"q": [a, b]} or {"qd": [a, b]}, "share"},
    share being the part of the residual's energy over moving rows that lies there. A q range is reported
    when the bins that stand out (`z` standard errors) cover less than half of the travel seen; a direction
    when the two directions' means differ by `z` standard errors of the difference.
    """
    moving = np.abs(qd) > min_speed_share * np.max(np.abs(qd))
    keep = np.zeros(len(q), bool)
    keep[::max(stride, 1)] = True
    use = moving & keep
    if use.sum() < 4 * bins:
        return ()
    f = (residual * np.sign(qd))[use]
    qs, qds = q[use], qd[use]
    energy = residual[moving] ** 2
    total = float(energy.sum()) or 1.0
    out = []
    edges = np.linspace(qs.min(), qs.max(), bins + 1)
    idx = np.clip(np.searchsorted(edges, qs, side="right") - 1, 0, bins - 1)
    mean = np.array([f[idx == b].mean() if np.any(idx == b) else 0.0 for b in range(bins)])
    se = np.array([f[idx == b].std(ddof=1) / np.sqrt((idx == b).sum()) if (idx == b).sum() > 2 else np.inf
                   for b in range(bins)])
    # against the other bins' level (the fitted Coulomb friction absorbed the average)
    rest = np.array([np.median(np.delete(mean, b)) for b in range(bins)])
    hot = (mean - rest) > z * se
    if 0 < hot.sum() < bins / 2:
        b = 0
        while b < bins:
            if not hot[b]:
                b += 1
                continue
            e = b
            while e + 1 < bins and hot[e + 1]:
                e += 1
            a_q, b_q = float(edges[b]), float(edges[e + 1])
            inside = moving & (q >= a_q) & (q <= b_q)
            share = float(np.sum(residual[inside] ** 2) / total)
            excess = float(np.mean(mean[b:e + 1] - rest[b:e + 1]))
            out.append({"summary": f"joint friction higher by about {excess:.1f}x the effort noise over "
                                   f"q = {a_q:.3f}-{b_q:.3f} {q_unit} ({100 * share:.0f} % of the residual while "
                                   "moving): friction that depends on position, no candidate models it",
                        "where": {"q": [a_q, b_q]}, "share": share})
            b = e + 1
    pos, neg = f[qds > 0], f[qds < 0]
    if len(pos) > 2 and len(neg) > 2:
        diff = pos.mean() - neg.mean()
        se_diff = np.sqrt(pos.var(ddof=1) / len(pos) + neg.var(ddof=1) / len(neg))
        if abs(diff) > z * se_diff:
            sign = 1.0 if diff > 0 else -1.0
            inside = moving & (np.sign(qd) == sign)
            share = float(np.sum(residual[inside] ** 2) / total)
            lo, hi = (0.0, float(qd.max())) if sign > 0 else (float(qd.min()), 0.0)
            out.append({"summary": f"joint friction higher by about {abs(diff):.1f}x the effort noise while "
                                   f"q' {'>' if sign > 0 else '<'} 0 than the other way ({100 * share:.0f} % of "
                                   f"the residual while moving, q' in {unit}): friction that depends on the "
                                   "direction, no candidate models it",
                        "where": {"qd": [lo, hi]}, "share": share})
    return tuple(sorted(out, key=lambda d: -d["share"]))
