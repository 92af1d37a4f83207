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


def _discs(ax, centres, disc_radii, temperature, norm, cmap, limits, scale):
    """Draw discs (centres ``[m, 2]``, radii ``[m]``, in m) coloured by temperature, in the given order."""
    from matplotlib.collections import PatchCollection
    from matplotlib.patches import Circle

    discs = [Circle(tuple(c * scale), r * scale) for c, r in zip(centres, disc_radii)]
    collection = PatchCollection(discs, cmap=cmap, norm=norm, edgecolor="k", linewidth=0.2)
    collection.set_array(temperature)
    ax.add_collection(collection)
    (x_lo, x_hi), (y_lo, y_hi) = limits * scale
    pad = 0.03 * max(x_hi - x_lo, y_hi - y_lo)
    ax.set_xlim(x_lo - pad, x_hi + pad)
    ax.set_ylim(y_lo - pad, y_hi + pad)
    ax.set_aspect("equal")
    return collection


RASTER_ABOVE = 5_000
"""Particles beyond which a view is drawn as an image of pixels (:func:`_raster_discs`) rather than a patch per disc."""


def _raster_discs(ax, centres, disc_radii, depth, temperature, norm, cmap, *, limits, scale, pixels=500):
    """Discs drawn as one image: each pixel shows the disc nearest the viewer (largest ``depth``) covering it.

    Vectorised over the discs, one pass per pixel offset within the largest disc (a disc smaller than a pixel
    covers the pixel of its centre), so a million discs take about a second instead of minutes of patches.
    """
    (x_lo, x_hi), (y_lo, y_hi) = limits
    size = max(x_hi - x_lo, y_hi - y_lo) / pixels
    width, height = int(np.ceil((x_hi - x_lo) / size)) + 1, int(np.ceil((y_hi - y_lo) / size)) + 1
    cx = np.floor((centres[:, 0] - x_lo) / size).astype(np.int64)
    cy = np.floor((centres[:, 1] - y_lo) / size).astype(np.int64)
    reach = disc_radii / size
    top = np.full(height * width, -np.inf)
    colour = np.full(height * width, np.nan)
    span = int(np.ceil(reach.max()))
    offsets = [(dx, dy) for dx in range(-span, span + 1) for dy in range(-span, span + 1)]
    for sweep in (0, 1):  # first the nearest depth per pixel, then the colour of the disc at that depth
        for dx, dy in offsets:
            hit = (dx * dx + dy * dy <= np.maximum(reach, 0.5) ** 2)
            x, y = cx[hit] + dx, cy[hit] + dy
            keep = (x >= 0) & (x < width) & (y >= 0) & (y < height)
            flat = y[keep] * width + x[keep]
            if sweep == 0:
                np.maximum.at(top, flat, depth[hit][keep])
            else:
                front = depth[hit][keep] == top[flat]
                colour[flat[front]] = temperature[hit][keep][front]
    image = ax.imshow(colour.reshape(height, width), origin="lower", cmap=cmap, norm=norm, interpolation="nearest",
                      extent=(x_lo * scale, (x_lo + width * size) * scale, y_lo * scale, (y_lo + height * size) * scale))
    pad = 0.03 * max(x_hi - x_lo, y_hi - y_lo) * scale
    ax.set_xlim(x_lo * scale - pad, x_hi * scale + pad)
    ax.set_ylim(y_lo * scale - pad, y_hi * scale + pad)
    ax.set_aspect("equal")
    return image


def state_picture(path, positions, radii, temperature, time=None, section_y=None,
                  title="sintercond run: final state"):
    """Write a PNG of the particles coloured by temperature: a top view and a vertical section.

    The top view projects along z (seen from above, the highest particles in
    front; each sphere a disc of its radius); the side view is the section by
    the plane y = ``section_y`` (default: through the hottest particle, so a
    beam's track is cut), each sphere it cuts shown as the disc of the cut.
    One colour scale for both, with a colour bar in K.

    Args:
      path: the PNG file to write.
      positions: ``[n, 3]`` centres (m).
      radii: ``[n]`` radii (m).
      temperature: ``[n]`` temperatures (K).
      time: the simulated time of the state (s), shown in the title when given.
      section_y: y of the vertical section (m); default the hottest particle's.
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
    lo, hi = (positions - radii[:, None]).min(axis=0), (positions + radii[:, None]).max(axis=0)
    fig = _figure(figsize=(11, 4.6), layout="constrained")
    top, side = fig.subplots(1, 2)
    # top view: every sphere projected along z, the highest in front
    if len(radii) > RASTER_ABOVE:
        mappable = _raster_discs(top, positions[:, :2], radii, positions[:, 2], temperature, norm, "inferno",
                                 limits=np.stack([lo[:2], hi[:2]], axis=1), scale=scale)
    else:
        order = np.argsort(positions[:, 2], kind="stable")
        mappable = _discs(top, positions[order][:, :2], radii[order], temperature[order], norm, "inferno",
                          np.stack([lo[:2], hi[:2]], axis=1), scale)
    # side view: the section y = y of the hottest particle; each cut sphere is the disc of its cut
    y_cut = positions[int(np.argmax(temperature)), 1] if section_y is None else float(section_y)
    cut = np.abs(positions[:, 1] - y_cut) < radii
    section = positions[cut][:, [0, 2]], np.sqrt(radii[cut] ** 2 - (positions[cut, 1] - y_cut) ** 2)
    if np.count_nonzero(cut) > RASTER_ABOVE:
        _raster_discs(side, *section, np.zeros(np.count_nonzero(cut)), temperature[cut], norm, "inferno",
                      limits=np.stack([lo[[0, 2]], hi[[0, 2]]], axis=1), scale=scale)
    else:
        _discs(side, *section, temperature[cut], norm, "inferno", np.stack([lo[[0, 2]], hi[[0, 2]]], axis=1), scale)
    top.set(xlabel=f"x [{unit}]", ylabel=f"y [{unit}]", title="top view (projection along z)")
    side.set(xlabel=f"x [{unit}]", ylabel=f"z [{unit}]",
             title=f"section y = {y_cut * scale:.4g} {unit}" + (" (through the hottest particle)"
                                                               if section_y is None else ""))
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
