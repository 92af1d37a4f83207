"""What a big run's last steps cost the user: the final picture, and one output frame in each encoding.

Usage: python benchmarks/run_outputs.py [--sizes 100000,1000000] [--repeats 3] [--no-write]

A cubic lattice of touching spheres with a hot spot, at each size:

* ``state_picture`` (the whole PNG: figure, both views, colour bar, savefig) as the run draws it, rasterised
  above ``plots.RASTER_ABOVE`` discs, against the obvious alternative, one matplotlib patch per disc (timed
  only up to 1e5: at 1e6 it takes minutes);
* one ``write_vtp`` frame, binary (appended, zlib-compressed, the default) against ASCII: seconds and bytes.

Times are the best of ``--repeats`` runs (the spread is printed). Writes the ``run_outputs`` section of
benchmarks/RESULTS.md unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from _common import command_line, markdown_table, write_section
from sintercond.output import io, plots


def lattice(n):
    side = round(n ** (1 / 3))
    grid = np.stack(np.meshgrid(*[np.arange(side)] * 3, indexing="ij"), -1).reshape(-1, 3) * 2e-5
    radii = np.full(len(grid), 1e-5)
    lateral = (grid[:, 0] - grid[:, 0].mean()) ** 2 + (grid[:, 1] - grid[:, 1].mean()) ** 2
    temperature = 300 + 500 * np.exp(-lateral / (0.1 * grid.max()) ** 2) * grid[:, 2] / grid[:, 2].max()
    return grid, radii, temperature


def timed(fn, repeats):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times), max(times)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--sizes", default="100000,1000000")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--no-write", action="store_true")
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        for n in (int(s) for s in args.sizes.split(",")):
            x, r, t = lattice(n)
            raster = timed(lambda: plots.state_picture(out / "p.png", x, r, t, 1e-3), args.repeats)
            patches = ("-", "-")
            if len(r) <= 100_000:
                saved = plots.RASTER_ABOVE
                plots.RASTER_ABOVE = 10**9
                try:
                    patches = timed(lambda: plots.state_picture(out / "q.png", x, r, t, 1e-3), 1)
                finally:
                    plots.RASTER_ABOVE = saved
            frames = {}
            for encoding in io.VTP_ENCODINGS:
                seconds = timed(lambda: io.write_vtp(out / f"{encoding}.vtp", x, r, t, 0, 0.0, encoding=encoding),
                                args.repeats)
                frames[encoding] = (seconds, (out / f"{encoding}.vtp").stat().st_size)
            rows.append((len(r), f"{raster[0]:.2f} ({raster[1]:.2f})",
                         patches[0] if patches[0] == "-" else f"{patches[0]:.1f}",
                         f"{frames['binary'][0][0]:.2f}", f"{frames['binary'][1] / 1e6:.1f}",
                         f"{frames['ascii'][0][0]:.2f}", f"{frames['ascii'][1] / 1e6:.1f}"))
            print(*rows[-1], sep="\t", flush=True)
    header = ("particles", "picture, image s (worst)", "picture, patches s", "VTP binary s", "VTP binary MB",
              "VTP ASCII s", "VTP ASCII MB")
    body = ("## Run outputs\n\nThe final picture (`plots.state_picture`, the whole PNG) drawn as an image above "
            f"{plots.RASTER_ABOVE:,} discs against one matplotlib patch per disc, and one VTP frame binary (the "
            "default) against ASCII, on a cubic lattice with a hot spot. Best of the repeats, worst in brackets.\n\n"
            + markdown_table(header, rows))
    if not args.no_write:
        write_section("run_outputs", command_line(), body)


if __name__ == "__main__":
    main()
