"""A picture of one estimate: pitch and roll over time with their 1-sigma, the status and the speed.

:func:`plot_estimate` draws THE output table (:func:`imu_ground.pipeline.output.track_table`) of any log
(``imu-ground estimate LOG --plot FILE.png``) with a :class:`~matplotlib.figure.Figure` of its own (no
``pyplot``: the caller's backend and figures are left alone). Angles in degrees, the body relative to
the road: pitch + nose down, roll + left side up; the band the calibrated 1-sigma, the shading the
status (:data:`~imu_ground.filters.status.STATUSES`), the grey line the measured speed (m/s).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from imu_ground.errors import ImuGroundError, require_extra
from imu_ground.filters.status import STATUSES

__all__ = ["PLOT_SUFFIXES", "STATUS_COLOURS", "check_plot_path", "estimate_figure", "plot_estimate"]

#: File suffixes a picture can be written as (matplotlib's format of that name).
PLOT_SUFFIXES = (".png", ".pdf", ".svg")
#: Shading colour of each status (``ok`` is left white: the shading shows what is not ok).
STATUS_COLOURS = {"converging": "#f4c27a", "ok": None, "standstill": "#b7e1a1", "gap": "#bdbdbd",
                  "degraded": "#f08080", "invalid": "#c9a0dc"}
#: Opacity of the status shading.
SHADE_ALPHA = 0.45


def check_plot_path(path: str | Path, option: str = "--plot") -> Path:
    """``path`` as a :class:`~pathlib.Path` if its suffix is one of :data:`PLOT_SUFFIXES`, else an
    :class:`~imu_ground.errors.ImuGroundError` naming it and ``option``."""
    p = Path(path)
    if p.suffix.lower() not in PLOT_SUFFIXES:
        raise ImuGroundError(f"{p}: unknown picture type {p.suffix or '(no suffix)'!r}; end the {option} file name "
                             f"with {', '.join(PLOT_SUFFIXES)}")
    return p


def _runs(values: np.ndarray) -> list[tuple[int, int]]:
    """``(start, stop)`` index ranges of the runs of equal consecutive values."""
    if not len(values):
        return []
    change = np.flatnonzero(values[1:] != values[:-1]) + 1
    starts = np.concatenate([[0], change])
    return list(zip(starts.tolist(), np.concatenate([change, [len(values)]]).tolist(), strict=True))


def plot_estimate(table: Any, path: str | Path, *, speed: Any = None, speed_note: str = "", title: str = "",
                  time_label: str = "t (s, frame end)") -> Path:
    """Write :func:`estimate_figure` (the keywords are its) to ``path``, in place, format by its suffix; returns it."""
    path = Path(path)
    fig = estimate_figure(table, speed=speed, speed_note=speed_note, title=title, time_label=time_label)
    fig.savefig(path, format=path.suffix.lower().lstrip(".") or "png")
    return path


def estimate_figure(table: Any, *, speed: Any = None, speed_note: str = "", title: str = "",
                    time_label: str = "t (s, frame end)") -> Any:
    """Pitch (top) and roll (bottom) over time with their 1-sigma band, the status as shading (:data:`STATUS_COLOURS`)
    and the speed on a second axis.

    Parameters
    ----------
    table : pandas.DataFrame
        THE output table: ``t``, ``pitch_deg``, ``roll_deg``; optional ``pitch_std_deg``, ``roll_std_deg``,
        ``status``. NaN values leave holes.
    speed : array_like (F,), optional
        Speed per row of ``table``, m/s (NaN: unknown); None or no finite value: no speed axis.
    speed_note, title, time_label : str
        What the speed is (or why there is none), the first title line, the time axis's label.

    Returns
    -------
    matplotlib.figure.Figure
        Its axes: pitch, roll, then (with a speed) the two speed axes.
    """
    require_extra("matplotlib", "plot", "pictures")
    from matplotlib.figure import Figure
    from matplotlib.patches import Patch

    t = np.asarray(table["t"], dtype=float)
    n = len(t)
    status = np.asarray(table["status"], dtype=object) if "status" in table else np.full(n, "ok", dtype=object)
    v = None if speed is None else np.asarray(speed, dtype=float).reshape(-1)
    if v is not None and (len(v) != n or not np.isfinite(v).any()):
        v = None
    fig = Figure(figsize=(11, 6.5), dpi=110)
    axes = fig.subplots(2, 1, sharex=True)
    # a frame covers (t_prev, t]: shade from the previous frame's end (the first frame: one median step back)
    step = float(np.nanmedian(np.diff(t))) if n > 1 else 0.1
    edges = np.concatenate([t[:1] - step, t])
    shown: dict[str, str] = {}
    for ax, name, sign_text in zip(axes, ("pitch", "roll"), ("+ nose down", "+ left side up"), strict=True):
        y = np.asarray(table[f"{name}_deg"], dtype=float)
        for a, b in _runs(status):
            colour = STATUS_COLOURS.get(str(status[a]), "#dddddd")
            if colour is None:
                continue
            ax.axvspan(edges[a], edges[b], color=colour, alpha=SHADE_ALPHA, lw=0, zorder=0)
            shown[str(status[a])] = colour
        if f"{name}_std_deg" in table:
            s = np.asarray(table[f"{name}_std_deg"], dtype=float)
            ax.fill_between(t, y - s, y + s, color="tab:blue", alpha=0.25, lw=0, zorder=2)
        ax.plot(t, y, color="tab:blue", lw=1.0, zorder=3)
        ax.set_ylabel(f"{name} (deg, {sign_text})")
        ax.grid(alpha=0.3, zorder=1)
        ax.set_axisbelow(True)
        if v is not None:
            ax2 = ax.twinx()
            ax2.plot(t, v, color="0.35", lw=0.8, alpha=0.8, zorder=1)
            ax2.set_ylabel("speed (m/s)", color="0.35")
            ax2.tick_params(axis="y", colors="0.35")
            ax2.set_ylim(bottom=0.0, top=max(1.0, float(np.nanmax(v))) * 1.05)
            ax.set_zorder(ax2.get_zorder() + 1)      # the estimate over the speed
            ax.patch.set_visible(False)
    axes[1].set_xlabel(time_label)
    handles: list = [axes[0].lines[0]]
    labels = ["estimate, body relative to the road"]
    if "pitch_std_deg" in table or "roll_std_deg" in table:
        handles.append(Patch(color="tab:blue", alpha=0.25))
        labels.append("1-sigma")
    if v is not None:
        handles.append(fig.axes[2].lines[0])
        labels.append("speed (right axis)")
    present = {str(s) for s in status}
    for st in [*STATUSES, *sorted(present - set(STATUSES))]:      # the statuses present, in their order
        if st in shown:
            handles.append(Patch(color=shown[st], alpha=SHADE_ALPHA))
            labels.append(f"status {st}")
        elif st in present:                            # ok: unshaded
            handles.append(Patch(facecolor="white", edgecolor="0.6"))
            labels.append(f"status {st} (unshaded)")
    heading = title or "ground estimate"
    note = speed_note if v is not None else (speed_note or "no speed")
    fig.suptitle(f"{heading}\nspeed: {note}" if note else heading, fontsize=10)
    fig.legend(handles, labels, loc="lower center", ncol=min(len(handles), 4), fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.035 * -(-len(handles) // 4) + 0.01, 1, 1))
    return fig
