"""report.html: what was identified, how well it fits, and whether every loader agrees."""

from __future__ import annotations

import base64
import html
import io
from pathlib import Path

import numpy as np


def _figure_png(fig) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    import matplotlib.pyplot as plt

    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode()


def _trajectory_plot(traces: dict) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.asarray(traces["t_s"])
    order = np.argsort(t, kind="stable")
    meas = np.asarray(traces["measured_position"])[order]
    fig, axes = plt.subplots(4, 1, figsize=(9, 9), sharex=True)
    for k, axis in enumerate("xyz"):
        ax = axes[k]
        ax.plot(t[order], meas[:, k], ".", ms=2, color="black", label="measured")
        for label, color in (("baseline", "tab:red"), ("final", "tab:blue")):
            sim = np.asarray(traces[f"{label}_position"])[order]
            ax.plot(t[order], sim[:, k], ".", ms=2, color=color, label=f"simulated ({label})")
        ax.set_ylabel(f"{axis} [m]")
    axes[0].legend(loc="upper right", markerscale=4)
    axes[0].set_title(f"Tracked frame, windows of {traces['window_s']:.2f} s replayed from measured states")
    for label, color in (("baseline", "tab:red"), ("final", "tab:blue")):
        err = np.linalg.norm(np.asarray(traces[f"{label}_position"]) - np.asarray(traces["measured_position"]), axis=1)
        axes[3].semilogy(t[order], np.maximum(err[order], 1e-7), ".", ms=2, color=color, label=label)
    axes[3].set_ylabel("position error [m]")
    axes[3].set_xlabel("time [s]")
    axes[3].legend(loc="upper right", markerscale=4)
    return _figure_png(fig)


def _loss_plot(loss_history) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 3))
    ax.semilogy(np.arange(1, len(loss_history) + 1), loss_history)
    ax.set_xlabel("loss evaluation")
    ax.set_ylabel("loss")
    ax.set_title("Identification loss (pose loss + lambda * bound penalty)")
    return _figure_png(fig)


def _fmt(x) -> str:
    if isinstance(x, (list, tuple)):
        return "[" + ", ".join(_fmt(v) for v in x) + "]"
    return f"{x:.5g}" if isinstance(x, float) else html.escape(str(x))


def write_report(path: Path, asset: dict, loss_history, traces: dict) -> None:
    """Write a self-contained HTML report (plots embedded as PNG)."""
    theta = asset["theta"]
    rows = "".join(
        f"<tr><td>{k}</td><td>{_fmt(v['value'])}</td><td>{_fmt(v['std'])}</td><td>{v.get('source', '')}</td></tr>"
        for k, v in theta.items()
    )
    fit = asset.get("fit", {})
    fit_rows = "".join(
        f"<tr><td>{k}</td><td>{fit[k]['rmse_position_m'] * 1000:.3f}</td><td>{fit[k]['rmse_rotation_rad']:.5f}</td>"
        f"<td>{fit[k]['loss']:.4g}</td></tr>"
        for k in ("baseline", "final") if k in fit
    )
    validation = asset.get("provenance", {}).get("validation", {})
    val_rows = "".join(
        f"<tr><td>{c['loader']}</td><td>{_fmt(c['mass'])}</td><td>{c['max_error']:.2e}</td>"
        f"<td>{'ok' if c['ok'] else 'FAIL: ' + html.escape(str(c.get('error') or ''))}</td></tr>"
        for c in validation.get("checks", [])
    )
    timings = asset.get("provenance", {}).get("timings_s", {})
    time_rows = "".join(f"<tr><td>{html.escape(k)}</td><td>{v:.2f}</td></tr>" for k, v in timings.items())
    loss_img = f'<img src="data:image/png;base64,{_loss_plot(loss_history)}">' if len(loss_history) else (
        "<p>Least-squares method: no iterative loss.</p>")
    doc = f"""<!doctype html>
<html><head><meta charset="utf-8"><title>twin: {html.escape(asset['name'])}</title>
<style>body{{font-family:sans-serif;max-width:1000px;margin:2em auto}}table{{border-collapse:collapse}}
td,th{{border:1px solid #ccc;padding:3px 8px;font-size:90%}}</style></head><body>
<h1>{html.escape(asset['name'])} ({asset['kind']})</h1>
<h2>Identified parameters (object frame, SI)</h2>
<table><tr><th>parameter</th><th>value</th><th>std</th><th>source</th></tr>{rows}</table>
<h2>Fit (window {fit.get('window_s', 0):.2f} s)</h2>
<table><tr><th></th><th>RMSE position [mm]</th><th>RMSE rotation [rad]</th><th>loss</th></tr>{fit_rows}</table>
<img src="data:image/png;base64,{_trajectory_plot(traces)}">
<h2>Loss</h2>{loss_img}
<h2>Exported files read back</h2>
<table><tr><th>loader</th><th>mass [kg]</th><th>max relative error</th><th></th></tr>{val_rows}</table>
<h2>Stage timings [s]</h2><table>{time_rows}</table>
</body></html>
"""
    Path(path).write_text(doc)
