"""Contact-table build: the previous jax-md + Python-loop build against the vectorised NumPy cell list.

Usage: python benchmarks/contact_build.py [--sizes 10000 100000] [--new-sizes 1000000] [--old-rev 43fe49a]

The packing is benchmarks/thermal_step.py's jittered sintered simple-cubic
lattice (~6 contacts per particle). Each (build, size) runs in a process of
its own so that its peak RSS is its own: 'first' is the first
``network.contact_table`` call of the process (with whatever it compiles),
'again' a second call on the same packing. The old build is
``sintercond/contacts/network.py`` as it was at ``--old-rev`` (read with ``git show``),
run against today's law modules; both builds must give the same contacts and
conductances (checked). Prints the table and rewrites its section of
benchmarks/RESULTS.md.
"""

import argparse
import hashlib
import json
import os
import pathlib
import resource
import subprocess
import sys
import time
import types

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the checkout this script lives in, not an installed sintercond

OLD_REV = "43fe49a"


def old_network(rev):
    """``sintercond/contacts/network.py`` at ``rev`` as a module."""
    source = subprocess.run(["git", "show", f"{rev}:sintercond/contacts/network.py"], cwd=ROOT, capture_output=True,
                            text=True, check=True).stdout
    module = types.ModuleType(f"network_{rev}")
    exec(compile(source, f"network@{rev}", "exec"), module.__dict__)
    return module


def child(build, n, rev):
    """One build at one size in this process; prints a JSON line."""
    import numpy as np
    from thermal_step import jittered_packing

    from sintercond.contacts import network

    module = old_network(rev) if build == "old" else network
    centres, radii = jittered_packing(n)
    times = []
    for _ in range(2):
        t0 = time.perf_counter()
        table = module.contact_table(centres, radii, 7.0)
        table.conductance.block_until_ready()
        times.append(time.perf_counter() - t0)
    pairs = table.pairs()
    pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]
    nbr, k = np.asarray(table.neighbors), np.asarray(table.conductance)
    rows = np.broadcast_to(np.arange(len(radii))[:, None], nbr.shape)
    upper = nbr > rows
    k_sorted = k[upper][np.lexsort((nbr[upper], rows[upper]))]  # K in the order of the sorted pairs
    print(json.dumps({
        "first": times[0], "again": times[1], "pairs": len(pairs),
        "digest": hashlib.sha1(pairs.astype(np.int64).tobytes()).hexdigest(),
        "k": k_sorted.tolist() if n <= 20_000 else float(np.sum(k_sorted)),
        "peak_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6,
    }))


def update_costs(n, skin_fraction=0.1, repeats=20):
    """Seconds per jitted ``update`` of a skinned list that only checks, and of one that rebuilds (skin 0):
    ``{(list, what): s}`` for the sorted cell list (`neighbors.neighbor_list`) and jax-md's Dense list."""
    import jax
    import jax.numpy as jnp
    from _common import best_time
    from thermal_step import jittered_packing

    from sintercond.contacts import neighbors

    centres, radii = jittered_packing(n)
    moved = jnp.asarray(centres + 1e-3 * radii.max())  # far below half the skin
    costs = {}
    for name, make in (("sorted cell list", neighbors.neighbor_list), ("jax-md Dense", neighbors.jax_md_neighbor_list)):
        for what, skin in (("check", skin_fraction * radii.max()), ("rebuild", 0.0)):
            fns = make(radii, skin, box_lo=centres.min(axis=0) - radii.max(), box_hi=centres.max(axis=0) + radii.max())
            nbrs = fns.allocate(centres)
            update = jax.jit(fns.update)
            assert bool(neighbors.did_rebuild(nbrs, update(moved, nbrs))) == (skin == 0.0)
            costs[name, what] = best_time(update, moved, nbrs, repeats=repeats)
    return costs


def run_child(build, n, rev):
    out = subprocess.run([sys.executable, __file__, "--child", build, str(n), "--old-rev", rev], cwd=ROOT,
                         capture_output=True, text=True, check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main():
    import numpy as np
    from _common import markdown_table, write_section

    parser = argparse.ArgumentParser()
    parser.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000])
    parser.add_argument("--new-sizes", type=int, nargs="*", default=[1_000_000], help="sizes for the new build only")
    parser.add_argument("--old-rev", default=OLD_REV)
    parser.add_argument("--dynamic-only", type=int, metavar="N", default=None,
                        help="only the dynamic-list paragraph, at N particles (rewritten inside the section)")
    parser.add_argument("--child", nargs=2, metavar=("BUILD", "N"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        return child(args.child[0], int(args.child[1]), args.old_rev)
    if args.dynamic_only:
        return dynamic_only(args.dynamic_only)
    rows = []
    for n in sorted(set(args.sizes) | set(args.new_sizes)):
        results = {build: run_child(build, n, args.old_rev) for build in ("old", "new")
                   if build == "new" or n in args.sizes}
        if "old" in results:
            old, new = results["old"], results["new"]
            assert old["digest"] == new["digest"], f"different contacts at n = {n}"
            np.testing.assert_allclose(new["k"], old["k"], rtol=1e-12)
        for build, r in results.items():
            speedup = f"{results['old']['again'] / r['again']:.0f}x" if "old" in results and build == "new" else ""
            rows.append((f"{n:,}", build, f"{r['pairs']:,}", f"{r['first']:.2f}", f"{r['again']:.3f}", speedup,
                         f"{r['peak_gb']:.2f}"))
            print(*rows[-1], sep="\t", flush=True)
    body = (
        "## Contact build: `network.contact_table` on a static packing\n\n"
        "Jittered sintered SC packing (`thermal_step.jittered_packing`, ~6 contacts per particle), kappa = 7. "
        f"'old' is `network.py` at {args.old_rev} (jax-md cell-list candidates, then a Python loop over rows and "
        "a dict lookup for the lower triangle); 'new' is the vectorised NumPy cell list (`neighbors."
        "cell_list_pairs`), `ell_table`, and the law compiled once on a power-of-two length. One process per "
        "row: 'first call' includes what that call compiles (jax-md's cell list for 'old', the law for both); "
        "peak RSS is the whole process's. Same contacts and K (to 1e-12) checked where both run.\n\n"
        + markdown_table(("particles", "build", "pairs", "first call (s)", "second call (s)", "speed-up (second)",
                          "peak RSS (GB)"), rows)
    )
    n_update = max(args.sizes)
    body += dynamic_paragraph(n_update)
    print(body.splitlines()[-1])
    write_section("contact_build", "python benchmarks/contact_build.py", body)


def dynamic_paragraph(n_update, command=None):
    """The section's paragraph on the dynamic list at ``n_update`` particles."""
    costs = update_costs(n_update)
    ours, theirs = costs["sorted cell list", "rebuild"], costs["jax-md Dense", "rebuild"]
    body = (
        f"\n\nDynamic list (`neighbors.neighbor_list`, a Dense table from a sorted cell list, jitted `update`) at "
        f"{n_update:,} particles moved by 1e-3 r_max: {costs['sorted cell list', 'check'] * 1e3:.2f} ms per update "
        f"that only checks the displacement (skin 0.1 r_max) against {ours * 1e3:.1f} ms per rebuild (skin 0): "
        f"{ours / costs['sorted cell list', 'check']:.0f}x. jax-md's own Dense list "
        f"(`neighbors.jax_md_neighbor_list`, what the step ran on before) in the same process: "
        f"{costs['jax-md Dense', 'check'] * 1e3:.2f} ms per check, {theirs * 1e3:.1f} ms per rebuild "
        f"({theirs / ours:.1f}x the sorted cell list's). Taken while other jobs shared the 2 cores "
        f"(load average {os.getloadavg()[0]:.1f})" + (f"; command: `{command}`." if command else ".")
    )
    return body


def dynamic_only(n):
    """Rewrite only the dynamic-list paragraph of the existing section (the static builds are not rerun)."""
    from _common import RESULTS

    text = RESULTS.read_text()
    paragraph = dynamic_paragraph(n, f"python benchmarks/contact_build.py --dynamic-only {n}").strip()
    print(paragraph)
    begin = text.index("<!-- BEGIN contact_build -->")
    at = text.index("Dynamic list (", begin)
    end = text.index("\n\nCommand:", at)
    RESULTS.write_text(text[:at] + paragraph + text[end:])


if __name__ == "__main__":
    main()
