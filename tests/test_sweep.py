"""Sharded, chunked sweeps: same numbers on 1 and 8 (simulated CPU) devices and any chunk size."""

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from sintercond import neck_radius
from sintercond.sweep import grid, sweep

SCRIPT = textwrap.dedent("""
    import json, sys
    import jax, numpy as np
    from sintercond import neck_radius, pair_conductance
    from sintercond.sweep import grid, sweep
    cases = grid(r_i=np.geomspace(1e-6, 1e-3, 37), ratio=np.geomspace(1.0, 1e3, 29), frac=np.linspace(0.0, 1.0, 23))
    def model(r_i, ratio, frac):
        from sintercond.laws.neck import max_overlap
        r_j = r_i * ratio
        h = frac * max_overlap(r_i, r_j)
        return {"a": neck_radius(r_i, r_j, h), "K": pair_conductance("rojek", r_i, r_j, h, 20.0)}
    out = sweep(model, cases, chunk_size=int(sys.argv[1]))
    print(json.dumps({"devices": jax.device_count(), "a": out["a"].tolist(), "K": out["K"].tolist()}))
""")


def _run(devices, chunk):
    env = dict(os.environ, XLA_FLAGS=f"--xla_force_host_platform_device_count={devices}", JAX_PLATFORMS="cpu")
    proc = subprocess.run([sys.executable, "-c", SCRIPT, str(chunk)], capture_output=True, text=True, env=env,
                          timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.mark.slow
def test_eight_devices_give_the_numbers_of_one():
    one = _run(1, 1 << 20)
    eight = _run(8, 5000)  # several chunks, the last one padded
    assert one["devices"] == 1 and eight["devices"] == 8
    assert len(one["a"]) == 37 * 29 * 23
    assert one["a"] == eight["a"] and one["K"] == eight["K"]  # bitwise
    assert np.all(np.isfinite(one["a"])) and np.all(np.isfinite(one["K"]))


def test_sweep_matches_direct_evaluation_and_handles_structures():
    cases = grid(r_i=[1.0, 2.0, 3.0], h=np.linspace(0.0, 0.5, 7))
    assert cases["r_i"].shape == (21,) and cases["h"][:7].tolist() == np.linspace(0.0, 0.5, 7).tolist()
    out = sweep(lambda r_i, h: neck_radius(r_i, 3.0, h), cases, chunk_size=4)
    # a different compiled program (vmapped chunk vs broadcast) may round differently: 1 ulp
    np.testing.assert_allclose(out, np.asarray(neck_radius(cases["r_i"], 3.0, cases["h"])), rtol=5e-16, atol=0)
    pair = sweep(lambda x, y: (x + y, x * y), (np.arange(5.0), np.arange(5.0)), chunk_size=2)
    np.testing.assert_array_equal(pair[0], 2 * np.arange(5.0))
    np.testing.assert_array_equal(pair[1], np.arange(5.0) ** 2)


def test_bad_input_is_named():
    with pytest.raises(ValueError, match="leading"):
        sweep(lambda x, y: x + y, (np.arange(3.0), np.arange(4.0)))
    with pytest.raises(ValueError, match="grid axis 'h'"):
        grid(h=[])
    with pytest.raises(ValueError, match="chunk_size"):
        sweep(lambda x: x, (np.arange(3.0),), chunk_size=0)
