"""Command-line entry point: ``sintercond [demo]``.

``sintercond demo`` (also the default with no arguments) prints the neck radii
and pair conductances of the cases of Rojek et al. (2022), computed by the
library, for copper (kappa = 394 W/(m K)).
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

# (r_i, r_j, h) in mm: the unequal pairs of Rojek et al. 2022, Sects. 4.3 and 6,
# and the equal-size overlaps h/r of their Figs. 13-14.
ROJEK_CASES_MM = (
    (1.0, 3.0, 0.2),
    (1.0, 3.0, 0.06),
    (1.0, 1.0, 0.02),
    (1.0, 1.0, 0.08),
    (1.0, 1.0, 0.2),
    (1.0, 1.0, 0.4),
)
COPPER_CONDUCTIVITY = 394.0  # W/(m K), Rojek et al. 2022, Sect. 5


def neck_table(cases_mm=ROJEK_CASES_MM, kappa=COPPER_CONDUCTIVITY) -> str:
    """The demo table as text: neck radii (mm) and conductances (W/K) per case."""
    from sintercond import conductance, neck

    r_i, r_j, h = (np.array(col, dtype=np.float64) for col in zip(*cases_mm))
    neck.validate_neck_inputs(r_i, r_j, h)
    m = 1e-3  # mm -> m
    columns = {
        "r_i": r_i,
        "r_j": r_j,
        "h": h,
        "h_max": neck.max_overlap(r_i, r_j),
        "a_coble": neck.coble_radius(r_i, r_j, h),
        "a_volume": neck.neck_radius(r_i, r_j, h),
        "a_lens": neck.intersection_radius(r_i, r_j, h),
        "a_hertz": neck.hertz_radius(r_i, r_j, h),
    }
    laws = ("rojek", "argento_bouvard", "batchelor_obrien", "conductivity")
    for law in laws:
        columns[f"K_{law}"] = conductance.pair_conductance(law, r_i * m, r_j * m, h * m, kappa)
    header = "  ".join(f"{name:>{_width(name)}}" for name in columns)
    lines = [
        f"Rojek et al. (2022) neck cases, copper kappa = {kappa:g} W/(m K); lengths in mm, conductances K in W/K",
        header,
        "-" * len(header),
    ]
    for row in zip(*(np.asarray(v) for v in columns.values())):
        lines.append("  ".join(f"{value:>{_width(name)}.6f}" for name, value in zip(columns, row)))
    lines += [
        "",
        "a_volume: volume-conserving cylindrical neck (Eqs. 19-20, 27); a_coble: Eqs. 11-12;",
        "a_lens: sphere intersection circle (Quintana-Ruiz Eqs. 33-34); a_hertz: sqrt(r* h).",
        "K_rojek: 1.064 kappa pi a halves in series (Eqs. 9, 43); K_argento_bouvard: slope 1/0.899;",
        "K_batchelor_obrien: 2 kappa a; K_conductivity: kappa pi a_lens^2 / d (Quintana-Ruiz Eq. 32).",
    ]
    return "\n".join(lines)


def _width(name: str) -> int:
    return max(len(name), 10)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(
        prog="sintercond",
        description="Differentiable heat conduction through sintered particles.",
    )
    sub = parser.add_subparsers(dest="command")
    demo = sub.add_parser("demo", help="print neck radii and pair conductances of the Rojek et al. (2022) cases")
    demo.add_argument("--kappa", type=float, default=COPPER_CONDUCTIVITY,
                      help="conductivity in W/(m K), > 0 (default: copper, 394)")
    args = parser.parse_args(argv)
    kappa = getattr(args, "kappa", COPPER_CONDUCTIVITY)
    if not (np.isfinite(kappa) and kappa > 0):
        parser.error(f"--kappa must be finite and > 0 W/(m K); got {kappa}")
    print(neck_table(kappa=kappa))
    return 0


if __name__ == "__main__":
    sys.exit(main())
