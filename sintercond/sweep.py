"""Batched parameter sweeps: vmap a model over millions of cases, in chunks, sharded over every device.

``sweep(fn, cases)`` evaluates ``fn`` once per case. The cases are cut into
chunks of ``chunk_size`` (so device memory stays bounded whatever the number
of cases); each chunk is laid out over a one-axis device mesh with
``jax.sharding.NamedSharding`` and one compiled ``jit(vmap(fn))`` runs on all
devices at once (XLA's SPMD partitioner gives each device its slice; an
elementwise model needs no communication). Chunks are dispatched
asynchronously, so the host prepares the next chunk while the devices work.
Results come back to the host as NumPy arrays.

Several GPUs on one host: nothing to do, every visible device is used
(``CUDA_VISIBLE_DEVICES`` selects them). Several hosts: call
``jax.distributed.initialize()`` on every process first (docs/sweeps.md); ``jax.devices()`` then lists the devices of all
hosts; every process runs the same ``sweep`` on the same cases, feeds the
devices it owns and gets every result back.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec


def grid(**axes) -> dict[str, np.ndarray]:
    """Cartesian product of 1-D value lists, flattened: ``grid(r_i=[...], h=[...])["h"]`` has ``len(r_i) len(h)``
    entries, the last axis varying fastest (``'ij'`` order, like ``np.meshgrid(..., indexing="ij")``)."""
    if not axes:
        raise ValueError("grid needs at least one axis")
    values = {name: np.asarray(v) for name, v in axes.items()}
    for name, v in values.items():
        if v.ndim != 1 or v.size == 0:
            raise ValueError(f"grid axis {name!r} must be a non-empty 1-D list of values; got shape {v.shape}")
    mesh = np.meshgrid(*values.values(), indexing="ij")
    return {name: m.ravel() for name, m in zip(values, mesh)}


def _batch_size(leaves) -> int:
    sizes = {np.shape(leaf)[0] if np.ndim(leaf) else None for leaf in leaves}
    if None in sizes or len(sizes) != 1:
        raise ValueError("every array of cases must have the same leading (case) dimension; got leading sizes "
                         f"{sorted(str(s) for s in sizes)}")
    return sizes.pop()


def _to_host(x):
    if x.is_fully_addressable:
        return np.asarray(x)
    from jax.experimental import multihost_utils  # several hosts: every process gets the whole chunk

    return np.asarray(multihost_utils.process_allgather(x, tiled=True))


def sweep(fn: Callable, cases: Mapping | Sequence, chunk_size: int = 1 << 20, devices: Sequence | None = None):
    """Evaluate ``fn`` on every case, chunked and sharded over ``devices``.

    Args:
      fn: the model for one case, ``fn(**case)`` if ``cases`` is a mapping, ``fn(*case)`` if a sequence;
        traceable and vmappable (every sintercond law and solver is).
      cases: arrays with the cases along their leading axis (e.g. from :func:`grid`).
      chunk_size: cases per compiled call (rounded up to a multiple of the device count); bounds device memory.
      devices: devices to shard over (default: all, ``jax.devices()``).

    Returns:
      ``fn``'s output structure with NumPy arrays of leading size ``n_cases``. The numbers do not depend on
      the device count or the chunk size (each case is computed alone).
    """
    as_mapping = isinstance(cases, Mapping)
    leaves = list(cases.values()) if as_mapping else list(cases)
    n = _batch_size(leaves)
    devices = list(jax.devices() if devices is None else devices)
    if chunk_size < 1:
        raise ValueError(f"chunk_size must be >= 1; got {chunk_size}")
    chunk = -(-min(chunk_size, max(n, 1)) // len(devices)) * len(devices)
    mesh = Mesh(np.array(devices), ("cases",))
    sharding = NamedSharding(mesh, PartitionSpec("cases"))

    def one(*case):
        return fn(**dict(zip(cases, case))) if as_mapping else fn(*case)

    run = jax.jit(jax.vmap(one), in_shardings=sharding, out_shardings=sharding)
    arrays = [np.asarray(leaf) for leaf in leaves]
    pending = []
    for start in range(0, n, chunk):
        stop = min(start + chunk, n)
        # the last chunk is padded with copies of its last case (valid input, results dropped)
        index = np.minimum(np.arange(start, start + chunk), stop - 1)
        pending.append((stop - start, run(*(jax.device_put(a[index], sharding) for a in arrays))))
    outputs = [jax.tree.map(lambda x, k=k: _to_host(x)[:k], out) for k, out in pending]
    return jax.tree.map(lambda *parts: np.concatenate(parts), *outputs)

