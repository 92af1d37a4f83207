"""Pictures of a run: the final state coloured by temperature, and the history curves.

So the result of ``sintercond run`` can be looked at without ParaView: PNG
files in the run directory, drawn with matplotlib's object API (no pyplot, so
no global backend or figure state; works headless). matplotlib is imported
inside the functions: importing ``sintercond`` does not load it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

STATE_PICTURE = "final_state.png"
HISTORY_PLOT = "history.png"

_AXIS_NAMES = "xyz"


def length_unit(extent: float) -> tuple[float, str]:
    """``(scale, label)`` to show lengths in m as µm (extent below 1 mm) or mm."""
    return (1e6, "µm") if extent < 1e-3 else (1e3, "mm")


def time_unit(seconds: float) -> tuple[float, str]:
    """``(scale, label)`` to show a time in s (or up to ``seconds``) in s, ms or µs."""
    return next((s, u) for s, u in ((1.0, "s"), (1e3, "ms"), (1e6, "µs")) if abs(seconds) * s >= 1.0 or u == "µs")


def time_label(seconds: float) -> str:
    """A time in s written in s, ms or µs, three significant digits."""
    scale, unit = time_unit(seconds)
    return f"{seconds * scale:.3g} {unit}"


def _figure(**kwargs):
    from matplotlib.figure import Figure

    return Figure(**kwargs)


def _project(ax, positions, radii, temperature, norm, cmap, axes, depth_axis, nearest_last, scale):
    """Draw the spheres as discs on the plane of ``axes``; the ones nearest the viewer on top."""
    from matplotlib.collections import PatchCollection
    from matplotlib.patches import Circle

    depth = positions[:, depth_axis] if nearest_last == "max" else -positions[:, depth_axis]
    order = np.argsort(depth, kind="stable")
    discs = [Circle((positions[k, axes[0]] * scale, positions[k, axes[1]] * scale), radii[k] * scale) for k in order]
    collection = PatchCollection(discs, cmap=cmap, norm=norm, edgecolor="k", linewidth=0.2)
    collection.set_array(temperature[order])
    ax.add_collection(collection)
    lo = (positions - radii[:, None]).min(axis=0) * scale
    hi = (positions + radii[:, None]).max(axis=0) * scale
    pad = 0.03 * float(np.max(hi - lo))
    ax.set_xlim(lo[axes[0]] - pad, hi[axes[0]] + pad)
    ax.set_ylim(lo[axes[1]] - pad, hi[axes[1]] + pad)
    ax.set_aspect("equal")
    return collection


def state_picture(path, positions, radii, temperature, time=None, title="sintercond run: final state"):
    """Write a PNG of the particles coloured by temperature: a top view and a side view.

    The top view projects along z (seen from above, the highest particles in
    front), the side view along y (seen from -y, the front row in front);
    each sphere is a disc of its radius. One colour scale for both, with a
    colour bar in K.

    Args:
      path: the PNG file to write.
      positions: ``[n, 3]`` centres (m).
      radii: ``[n]`` radii (m).
      temperature: ``[n]`` temperatures (K).
      time: the simulated time of the state (s), shown in the title when given.
      title: the figure title.

    Returns:
      the path written, as a ``Path``.
    """
    from matplotlib.colors import Normalize

    positions = np.asarray(positions, dtype=float).reshape(-1, 3)
    radii = np.asarray(radii, dtype=float).reshape(-1)
    temperature = np.asarray(temperature, dtype=float).reshape(-1)
    if not (len(positions) == len(radii) == len(temperature)) or len(radii) == 0:
        raise ValueError(f"positions [n, 3], radii [n] and temperature [n] must agree and n > 0; got "
                         f"{len(positions)}, {len(radii)}, {len(temperature)}")
    extent = float(np.max((positions + radii[:, None]).max(0) - (positions - radii[:, None]).min(0)))
    scale, unit = length_unit(extent)
    t_lo, t_hi = float(temperature.min()), float(temperature.max())
    if t_hi - t_lo < 1e-9 * max(1.0, abs(t_hi)):
        t_lo, t_hi = t_lo - 0.5, t_hi + 0.5
    norm = Normalize(t_lo, t_hi)
    fig = _figure(figsize=(11, 4.6), layout="constrained")
    top, side = fig.subplots(1, 2, width_ratios=[1, 1])
    mappable = _project(top, positions, radii, temperature, norm, "inferno", (0, 1), 2, "max", scale)
    _project(side, positions, radii, temperature, norm, "inferno", (0, 2), 1, "min", scale)
    top.set(xlabel=f"x [{unit}]", ylabel=f"y [{unit}]", title="top view (projection along z)")
    side.set(xlabel=f"x [{unit}]", ylabel=f"z [{unit}]", title="side view (projection along y)")
    fig.colorbar(mappable, ax=[top, side], label="T [K]", shrink=0.9)
    fig.suptitle(title if time is None else f"{title} at t = {time_label(time)}"
                 f"  (T from {float(temperature.min()):.1f} K to {float(temperature.max()):.1f} K)")
    path = Path(path)
    fig.savefig(path, dpi=110)
    return path


def _unit_of(name: str) -> str:
    """The unit a history key names by its suffix (``heat_in_W`` -> W); temperatures ``T*`` are in K."""
    for suffix in ("K", "W", "J", "s", "m"):
        if name.endswith("_" + suffix):
            return suffix
    return "K" if name.startswith("T") else ""


def history_plot(path, history, title="sintercond run: history"):
    """Write a PNG of a run's history curves against time.

    Args:
      path: the PNG file to write.
      history: a dict of 1-D arrays of one length: ``"time"`` (s), and any
        curves. Keys starting with ``T`` are temperatures in K (``T_mean``,
        ``T_min``, ``T_max``, ...) and share the first panel; every other key
        gets a panel of its own, its unit read from a suffix (``heat_in_W``:
        W; known suffixes K, W, J, s, m).
      title: the figure title.

    Returns:
      the path written, as a ``Path``.
    """
    if "time" not in history:
        raise ValueError(f"history needs a 'time' array (s); got keys {sorted(history)}")
    t = np.asarray(history["time"], dtype=float).reshape(-1)
    curves = {k: np.asarray(v, dtype=float).reshape(-1) for k, v in history.items() if k != "time"}
    if not curves or len(t) == 0:
        raise ValueError("history needs at least one curve besides 'time', with at least one point")
    bad = [k for k, v in curves.items() if len(v) != len(t)]
    if bad:
        raise ValueError(f"history curves {bad} do not have the length of 'time' ({len(t)})")
    temperatures = [k for k in curves if k.startswith("T")]
    others = [k for k in curves if not k.startswith("T")]
    panels = ([temperatures] if temperatures else []) + [[k] for k in others]
    t_scale, t_unit = time_unit(float(np.max(np.abs(t))))
    fig = _figure(figsize=(6.5, 2.2 + 2.0 * len(panels)), layout="constrained")
    axes = np.atleast_1d(fig.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0])
    styles = {"T_max": "-", "T_mean": "--", "T_min": ":"}
    for ax, keys in zip(axes, panels):
        for k in keys:
            ax.plot(t * t_scale, curves[k], styles.get(k, "-"), marker="." if len(t) < 30 else None, label=k)
        unit = _unit_of(keys[0])
        name = "T" if keys is temperatures else keys[0].removesuffix("_" + unit)
        ax.set_ylabel(f"{name} [{unit}]" if unit else name)
        ax.grid(alpha=0.3)
        if len(keys) > 1:
            ax.legend()
    axes[-1].set_xlabel(f"time [{t_unit}]")
    fig.suptitle(title)
    path = Path(path)
    fig.savefig(path, dpi=110)
    return path


def write_run_pictures(out_dir, positions, radii, temperature, summary, history=None):
    """The pictures of a finished run in ``out_dir``: the final state, and the history when one was recorded.

    Returns:
      the paths written.
    """
    out = Path(out_dir)
    written = [state_picture(out / STATE_PICTURE, positions, radii, temperature, summary.get("simulated_s"))]
    if history is not None:
        written.append(history_plot(out / HISTORY_PLOT, history))
    return written
