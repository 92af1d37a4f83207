"""Shared pieces of the benchmark scripts: inputs, references, timing, RESULTS.md."""

from __future__ import annotations

import datetime
import os
import pathlib
import platform
import re
import sys
import time

import jax
import numpy as np

import sintercond  # noqa: F401  (float64 on)
from sintercond.laws.neck import max_overlap

RESULTS = pathlib.Path(__file__).resolve().parent / "RESULTS.md"
FIGURES = RESULTS.parent / "figures"


def random_pairs(n, seed=0, max_ratio=1e3, frac_low=0.0, frac_high=1.0):
    """Random (r_i, r_j, h): radii log-uniform in [1e-3, 1e3] (any unit), ratio
    log-uniform up to ``max_ratio`` either way, h uniform in
    ``[frac_low, frac_high] * max_overlap``."""
    rng = np.random.default_rng(seed)
    r_i = np.exp(rng.uniform(np.log(1e-3), np.log(1e3), n))
    r_j = r_i * np.exp(rng.uniform(-np.log(max_ratio), np.log(max_ratio), n))
    h = rng.uniform(frac_low, frac_high, n) * np.asarray(max_overlap(r_i, r_j))
    return r_i, r_j, h


def cap_height(a, r):
    return a**2 / (r + np.sqrt((r - a) * (r + a)))


def rojek_residual(a, r_i, r_j, h):
    """Rojek et al. 2022, Eq. 27 (r_k per cap), in whatever precision ``a`` has."""
    h_ci, h_cj = cap_height(a, r_i), cap_height(a, r_j)
    return 3 * a**2 * (h_ci + h_cj - h) - h_ci**2 * (3 * r_i - h_ci) - h_cj**2 * (3 * r_j - h_cj)


def lens_radius(r_i, r_j, h):
    """Radius of the intersection circle of two overlapping spheres (NumPy, the precision of the input)."""
    d = r_i + r_j - h
    return np.sqrt(h * (2 * (r_i + r_j) - h) * (2 * r_i - h) * (2 * r_j - h)) / (2 * d)


def reference_neck_gradient(a, r_i, r_j, h):
    """``(da/dr_i, da/dr_j, da/dh)`` at a root ``a`` of Eq. 27, by the implicit function theorem, in 80-bit.

    With ``h_c = r - sqrt(r^2 - a^2)`` and ``a^2 = 2 r h_c - h_c^2`` Eq. 27 gives ``dZ/da = 6 a h_n``
    (``h_n = h_ci + h_cj - h``), ``dZ/dh = -3 a^2`` and ``dZ/dr_k = -3 h_ck^2``; so ``da/dh = a / (2 h_n)`` and
    ``da/dr_k = h_ck^2 / (2 a h_n)``. Independent of the library's own (scaled) derivative formulas.
    """
    ld = np.longdouble
    a, r_i, r_j, h = (np.asarray(x, dtype=ld) for x in (a, r_i, r_j, h))
    h_ci, h_cj = cap_height(a, r_i), cap_height(a, r_j)
    h_n = h_ci + h_cj - h
    return h_ci**2 / (2 * a * h_n), h_cj**2 / (2 * a * h_n), a / (2 * h_n)


def reference_neck_radius(r_i, r_j, h, iterations=160):
    """Bracketing reference: bisection of Eq. 27 in 80-bit extended precision.

    The bracket is [lens radius, min(r_i, r_j)], which holds exactly the
    physical root. Bisection is geometric (midpoint sqrt(lo hi)), so the
    bracket shrinks in relative terms even for a ~ 1e-150; 160 halvings of
    its logarithm leave far below 1e-15 relative.
    """
    ld = np.longdouble
    r_i, r_j, h = (np.asarray(x, dtype=ld) for x in (r_i, r_j, h))
    lo = lens_radius(r_i, r_j, h)
    hi = np.minimum(r_i, r_j)
    for _ in range(iterations):
        mid = np.sqrt(lo * hi)
        negative = rojek_residual(mid, r_i, r_j, h) < 0
        lo, hi = np.where(negative, mid, lo), np.where(negative, hi, mid)
    return np.sqrt(lo * hi).astype(np.float64)


def numpy_neck_radius(r_i, r_j, h, iterations=5):
    """The library's Newton (reduced Eq. 27 in u = a^2, Coble start), vectorised NumPy."""
    u_max = np.minimum(r_i, r_j) ** 2
    u = np.minimum(4.0 * h * r_i * r_j / (r_i + r_j), u_max)
    for _ in range(iterations):
        s_i = np.sqrt(np.maximum(r_i * r_i - u, 0.0))
        s_j = np.sqrt(np.maximum(r_j * r_j - u, 0.0))
        w_i = 1.0 / (3.0 * (r_i + s_i) ** 2)
        w_j = 1.0 / (3.0 * (r_j + s_j) ** 2)
        f = u * ((r_i + 2 * s_i) * w_i + (r_j + 2 * s_j) * w_j) - h
        df = (2 * r_i + s_i) * w_i + (2 * r_j + s_j) * w_j
        u = np.clip(u - f / df, 0.0, u_max)
    return np.sqrt(u)


def best_time(fn, *args, repeats=25, max_seconds=10.0):
    """Best wall time of ``fn(*args)`` (blocking on JAX results), after a warm-up call.

    The minimum over many repeats: this machine is a shared VM whose timings
    scatter by 2x from run to run; the minimum is the stable statistic.
    """
    jax.block_until_ready(fn(*args))
    best = np.inf
    start = time.perf_counter()
    for i in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(*args))
        best = min(best, time.perf_counter() - t0)
        if i >= 3 and time.perf_counter() - start > max_seconds:
            break
    return best


def machine_line() -> str:
    dev = jax.devices()[0]
    return (
        f"{datetime.date.today().isoformat()}, {platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} CPU cores, JAX {jax.__version__} on {dev.platform}"
        f" ({dev.device_kind}), NumPy {np.__version__}"
    )


def command_line() -> str:
    """The command that ran this script, as RESULTS.md should record it (arguments included)."""
    return " ".join(["python", f"benchmarks/{pathlib.Path(sys.argv[0]).name}", *sys.argv[1:]])


def sintercond_process(argv):
    """``(completed, wall)``: the ``sintercond`` command with ``argv`` run in a new Python process (its output
    captured), and that process's wall time (s): what a user waits for."""
    import subprocess

    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", f"from sintercond.cli import main; raise SystemExit(main({argv!r}))"],
                          capture_output=True, text=True)
    return done, time.perf_counter() - start


def write_section(name: str, command: str, body: str) -> None:
    """Replace (or append) the section ``name`` of RESULTS.md."""
    begin, end = f"<!-- BEGIN {name} -->", f"<!-- END {name} -->"
    section = f"{begin}\n{body.rstrip()}\n\nCommand: `{command}` ({machine_line()})\n{end}"
    text = RESULTS.read_text() if RESULTS.exists() else "# Benchmark results\n"
    pattern = re.compile(re.escape(begin) + ".*?" + re.escape(end), re.S)
    text = pattern.sub(lambda _: section, text) if pattern.search(text) else text.rstrip() + "\n\n" + section + "\n"
    RESULTS.write_text(text)


def markdown_table(header, rows) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(str(c).replace("|", "\\|") for c in row) + " |" for row in rows]  # "|" in a cell
    return "\n".join(lines)


def new_figure(width=6.4, height=4.2):
    """A matplotlib Figure of the object API (no pyplot: no backend or global state), laid out tightly."""
    from matplotlib.figure import Figure

    return Figure(figsize=(width, height), layout="constrained")


def save_figure(name: str, fig, caption: str) -> str:
    """Write ``fig`` to ``benchmarks/figures/<name>.png``; returns the markdown that shows it in RESULTS.md."""
    FIGURES.mkdir(exist_ok=True)
    fig.savefig(FIGURES / f"{name}.png", dpi=110)
    return f"![{caption}](figures/{name}.png)"


def number(cell) -> float:
    """A table cell as written by the scripts ("1,000", "2.5e+06", "3.1x stable") read back as a float."""
    return float(re.match(r"\s*([-+0-9.,eE]+)", str(cell)).group(1).replace(",", ""))
