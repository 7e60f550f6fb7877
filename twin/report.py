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
    """The replayed windows against the measured track: x, y, z (x, y and the heading for a pushed object,
    whose traces carry headings) and the errors, at the prior's parameters and the identified ones."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.asarray(traces["t_s"])
    order = np.argsort(t, kind="stable")
    t = t - t[order[0]]  # bag stamps are epoch seconds
    runs = {"measured": "black", "baseline": "tab:red", "final": "tab:blue"}
    labels = {"measured": "measured", "baseline": "simulated, prior", "final": "simulated, identified"}
    position = {k: np.asarray(traces[f"{k}_position"])[order] for k in runs}
    planar = "measured_heading_rad" in traces
    axes_named = "xy" if planar else "xyz"
    channels = [(f"{a} [m]", {k: p[:, i] for k, p in position.items()}) for i, a in enumerate(axes_named)]
    if planar:
        channels.append(("heading [deg]", {k: np.degrees(np.asarray(traces[f"{k}_heading_rad"]))[order] for k in runs}))
    errors = [("position error [m]", {k: np.linalg.norm(position[k] - position["measured"], axis=1)
                                      for k in ("baseline", "final")})]
    if planar:
        errors.append(("heading error [deg]", {k: np.abs(v - channels[-1][1]["measured"])
                                               for k, v in channels[-1][1].items() if k != "measured"}))
    fig, axes = plt.subplots(len(channels) + len(errors), 1, figsize=(9, 2.3 * (len(channels) + len(errors))),
                             sharex=True)
    for ax, (name, series) in zip(axes, channels):
        for k, v in series.items():
            ax.plot(t[order], v, ".", ms=2, color=runs[k], label=labels[k])
        ax.set_ylabel(name)
    for ax, (name, series) in zip(axes[len(channels):], errors):
        for k, v in series.items():
            shown = v > 0  # each window starts at the measured state
            ax.semilogy(t[order][shown], v[shown], ".", ms=2, color=runs[k], label=labels[k])
        ax.set_ylabel(name)
    axes[0].legend(loc="upper right", markerscale=4)
    axes[0].set_title(f"{traces.get('replayed', 'Tracked frame').capitalize()}: windows of {traces['window_s']:.2f} s "
                      "replayed from measured states")
    axes[-1].set_xlabel("time since the first window [s]")
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


def diagnosis_plots(traces: dict) -> str:
    """Residual (noise units) and position error over time, before and after the chosen effects; a PNG,
    base64-encoded."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.asarray(traces["residual_t_s"])
    # several evaluation recordings, each on its own clock, interleave in time: points, not a line between them
    style = {"lw": 0.8} if np.all(np.diff(t) >= 0) else {"ls": "none", "marker": ".", "ms": 2}
    # a wrench residual has force and torque channels, a pushed object's replay position and heading errors,
    # a joint's one effort channel
    parts = {6: ((slice(0, 3), "force"), (slice(3, 6), "torque")),
             3: ((slice(0, 2), "position"), (slice(2, 3), "heading arc"))}.get(
        np.asarray(traces["residual_before"]).shape[1], ((slice(0, 1), "joint effort"),))
    fig, axes = plt.subplots(len(parts) + 1, 1, figsize=(9, 8), sharex=True)
    for ax, (part, label) in zip(axes, parts):
        for key, color in (("residual_before", "tab:red"), ("residual_after", "tab:blue")):
            r = np.linalg.norm(np.asarray(traces[key])[:, part], axis=1)
            t_key = np.asarray(traces.get(f"{key}_t_s", t))  # its own rows where they differ (a delay)
            order = np.argsort(t_key, kind="stable")
            ax.plot(t_key[order], r[order], color=color, label=key.split("_")[1], **style)
        ax.set_ylabel(f"|{label} residual| [noise]")
    axes[0].legend(loc="upper right")
    axes[0].set_title("What the model leaves unexplained, before and after the chosen effects")
    tp = np.asarray(traces["t_s"])
    order = np.argsort(tp, kind="stable")
    measured = np.asarray(traces["measured_position"])
    for key, color in (("before_position", "tab:red"), ("after_position", "tab:blue")):
        err = np.linalg.norm(np.asarray(traces[key]) - measured, axis=1)
        axes[-1].semilogy(tp[order], np.maximum(err[order], 1e-7), ".", ms=2, color=color, label=key.split("_")[0])
    axes[-1].set_ylabel("position error [m]")
    axes[-1].set_xlabel("time [s]")
    axes[-1].legend(loc="upper right", markerscale=4)
    return _figure_png(fig)


def diagnosis_section(asset: dict, traces: dict | None) -> str:
    """The diagnose stage's findings: effects, unexplained mismatches, residual analysis, fit before/after."""
    d = asset.get("provenance", {}).get("diagnose")
    if not d:
        return ""
    if "skipped" in d:
        return f"<h2>Diagnosis</h2><p>Skipped: {html.escape(str(d['skipped']))}</p>"
    effects = "".join(
        f"<tr><td>{html.escape(e['name'])}</td><td>{_fmt(e['params'])}</td>"
        f"<td>{_fmt(e['evidence'].get('std', ''))}</td>"
        f"<td>{_fmt(e['evidence'].get('inclusion_probability', ''))}</td>"
        f"<td>{html.escape(str(e['evidence'].get('belongs', '')))}</td></tr>"
        for e in asset.get("effects", [])
    ) or "<tr><td colspan=5>none: no candidate improves the held-out prediction</td></tr>"
    unexplained = "".join(f"<li>{html.escape(u['summary'])}</li>" for u in asset.get("unexplained", [])) or "<li>none</li>"
    findings = "".join(f"<li>{html.escape(f)}</li>" for f in d.get("findings", [])) or "<li>residual white</li>"
    inclusion = ", ".join(f"{html.escape(k)} {v:.2f}" for k, v in d["screening"]["inclusion"].items())
    # the error no model of this recording can remove, beside what the models left
    floor = d.get("noise_floor", {})
    rows = {**d["fits"], **({"sensor noise alone (estimated)": floor} if floor else {}),
            **({"sensor noise alone, unsmoothed (estimated)": floor["unsmoothed"]} if "unsmoothed" in floor else {})}
    fits = "".join(f"<tr><td>{k}</td><td>{v['rmse_position_m'] * 1000:.3f}</td><td>{v['rmse_rotation_rad']:.5f}</td>"
                   "</tr>" for k, v in rows.items())
    plot = f'<img src="data:image/png;base64,{diagnosis_plots(traces)}">' if traces else ""
    return f"""<h2>Diagnosis ({html.escape(d['evaluation'])})</h2>
<table><tr><th>effect</th><th>params (SI)</th><th>standard deviation</th><th>inclusion probability</th><th>belongs to</th></tr>{effects}</table>
<p>Screening inclusion probabilities: {inclusion}</p>
<h3>Unexplained</h3><ul>{unexplained}</ul>
<h3>Residual before diagnosis</h3><ul>{findings}</ul>
<table><tr><th>Newton replay</th><th>RMSE position [mm]</th><th>RMSE rotation [rad]</th></tr>{fits}</table>
{plot}
"""


def _fmt(x) -> str:
    if isinstance(x, (list, tuple)):
        return "[" + ", ".join(_fmt(v) for v in x) + "]"
    if isinstance(x, dict):
        return ", ".join(f"{html.escape(k)}={_fmt(v)}" for k, v in x.items())
    return f"{x:.5g}" if isinstance(x, float) else html.escape(str(x))


def summary_section(asset: dict) -> str:
    from twin.summary import summary_lines

    flagged = ' style="color:#b00"'
    items = "".join(f"<li{flagged if line.startswith('FLAG') else ''}>{html.escape(line)}</li>"
                    for line in summary_lines(asset))
    return f"<h2>Summary</h2><ul>{items}</ul>" if items else ""


def write_report(path: Path, asset: dict, loss_history, traces: dict | None,
                 diagnosis_traces: dict | None = None) -> None:
    """Write a self-contained HTML report (plots embedded as PNG); `traces` None (a diagnosis alone) leaves
    out the identification's replay plot."""
    theta = asset["theta"]
    # a pushed object's friction comes from the sliding fit or, where that only bounds it, the wrench balance
    how = {"friction": asset.get("provenance", {}).get("identify", {}).get("friction_from")}
    rows = "".join(
        f"<tr><td>{k}</td><td>{_fmt(v['value'])}</td><td>{_fmt(v['std'])}</td><td>{v.get('source', '')}"
        f"{f' ({html.escape(how[k])})' if how.get(k) else ''}</td></tr>"
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
    sessions = asset.get("provenance", {}).get("scan", {}).get("sessions", [])
    session_rows = "".join(
        f"<tr><td>{html.escape(s['root'])}</td><td>{s['volume_m3'] * 1e6:.2f}</td>"
        + (f"<td>{s['registration']['fitness']:.3f}</td><td>{s['registration']['rmse_m'] * 1000:.3f}</td>"
           f"<td>{s['registration']['overlap']:.2f}</td>" if "registration" in s
           else "<td colspan=3>first: defines the placement</td>")
        + "</tr>"
        for s in sessions
    )
    session_table = (
        "<h2>Scan sessions (intersected)</h2><table><tr><th>session</th><th>own solid [cm^3]</th><th>fitness</th>"
        f"<th>RMSE [mm]</th><th>overlap</th></tr>{session_rows}</table>" if sessions else "")
    timings = asset.get("provenance", {}).get("timings_s", {})
    time_rows = "".join(f"<tr><td>{html.escape(k)}</td><td>{v:.2f}</td></tr>" for k, v in timings.items())
    loss_img = f'<img src="data:image/png;base64,{_loss_plot(loss_history)}">' if len(loss_history) else (
        "<p>Least-squares method: no iterative loss.</p>")
    trajectory_img = f'<img src="data:image/png;base64,{_trajectory_plot(traces)}">' if traces else ""
    doc = f"""<!doctype html>
<html><head><meta charset="utf-8"><title>twin: {html.escape(asset['name'])}</title>
<style>body{{font-family:sans-serif;max-width:1000px;margin:2em auto}}table{{border-collapse:collapse}}
td,th{{border:1px solid #ccc;padding:3px 8px;font-size:90%}}</style></head><body>
<h1>{html.escape(asset['name'])} ({asset['kind']})</h1>
{summary_section(asset)}
<h2>Identified parameters (object frame, SI)</h2>
<table><tr><th>parameter</th><th>value</th><th>std</th><th>source</th></tr>{rows}</table>
{session_table}
<h2>Fit (window {fit.get('window_s', 0):.2f} s)</h2>
<table><tr><th></th><th>RMSE position [mm]</th><th>RMSE rotation [rad]</th><th>loss</th></tr>{fit_rows}</table>
{trajectory_img}
<h2>Loss</h2>{loss_img}
{diagnosis_section(asset, diagnosis_traces)}
<h2>Exported files read back</h2>
<table><tr><th>loader</th><th>mass [kg]</th><th>max relative error</th><th></th></tr>{val_rows}</table>
<h2>Stage timings [s]</h2><table>{time_rows}</table>
</body></html>
"""
    Path(path).write_text(doc)
