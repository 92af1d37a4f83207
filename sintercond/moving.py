"""Conduction in a packing whose particles move: neighbour lists updated under jit, overflow recovered.

The positions follow a prescribed motion ``positions_fn(t) -> [n, 3]`` (for
example the affine shrinkage of a sintering compact, :func:`affine_shrinkage`);
the thermo-mechanical DEM will supply integrated positions through the same
loop. Every step recomputes the overlaps, necks and conductances of the
candidate pairs of a jax-md neighbour list (Dense format), which is updated
every step inside ``lax.scan``. A neighbour buffer that overflows is only a
flag under jit: after each chunk the host checks it, reallocates a larger
list from the chunk's starting positions and redoes the chunk from its saved
state, so no contact is ever lost (jax-md ``partition``; tested against a
brute-force contact list).
"""

from __future__ import annotations

import functools
import warnings

import jax
import jax.numpy as jnp
import numpy as np

from sintercond.conductance import pair_conductance


def _partition():
    with jax.numpy_dtype_promotion("standard"), warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="scatter inputs have incompatible types", category=FutureWarning)
        from jax_md import partition, space
    return partition, space


def affine_shrinkage(centres, rate):
    """Positions shrinking toward the centroid at a linear strain ``rate`` (1/s): ``c0 + (1 - rate t)(c - c0)``."""
    centres = jnp.asarray(centres)
    centroid = jnp.mean(centres, axis=0)
    return lambda t: centroid + (1.0 - rate * t) * (centres - centroid)


def neighbor_conductance(positions, radii, kappa, idx, law="rojek", params=None, neck_model=None):
    """Conductances ``[n, m]`` of a jax-md Dense neighbour table ``idx`` (padding ``n``) at ``positions``."""
    n = positions.shape[0]
    valid = idx < n
    j = jnp.where(valid, idx, 0)
    d = jnp.linalg.norm(positions[:, None, :] - positions[j], axis=-1)
    h = jnp.where(valid, radii[:, None] + radii[j] - d, -1.0)
    k = pair_conductance(law, radii[:, None], radii[j], h, kappa, params=params, neck_model=neck_model)
    return jnp.where(valid, k, 0.0), j


def simulate_moving(temperature, positions_fn, radii, kappa, capacity, dt, n_steps, chunk=100, law="rojek",
                    params=None, neck_model=None, capacity_multiplier=1.25):
    """Explicit Euler conduction while particles move; returns ``(final temperatures, report)``.

    Args:
      temperature: ``[n]`` initial temperatures (K).
      positions_fn: ``t -> [n, 3]`` positions (m), traceable.
      radii: ``[n]`` (m). kappa: conductivity (W/(m K)). capacity: ``[n]`` (J/K).
      dt: time step (s); choose it below the stable step of the densest state.
      n_steps, chunk: total steps and steps per compiled chunk (the overflow
        check runs between chunks).
      capacity_multiplier: spare neighbour capacity of each allocation.

    Returns:
      The final temperatures and a dict with the number of reallocations and
      the final neighbour capacity.
    """
    partition, space = _partition()
    radii = jnp.asarray(radii)
    cutoff = 2.0 * float(jnp.max(radii))
    displacement, _ = space.free()
    # one cell-list box for the whole run: the initial extent with a margin of
    # half its size on every side; positions leaving it are refused below
    start = np.asarray(positions_fn(0.0))
    extent = start.max(axis=0) - start.min(axis=0)
    lo = start.min(axis=0) - 0.5 * extent - cutoff
    hi = start.max(axis=0) + 0.5 * extent + cutoff
    shift, box = jnp.asarray(lo), jnp.asarray(hi - lo)
    fn = partition.neighbor_list(displacement, box, cutoff, capacity_multiplier=capacity_multiplier,
                                 format=partition.NeighborListFormat.Dense)

    def allocate(t):
        positions = np.asarray(positions_fn(t))
        if np.any(positions < lo) or np.any(positions > hi):
            raise ValueError(f"particles left the neighbour-list box at t = {t:.6g} s; motion too large")
        with jax.numpy_dtype_promotion("standard"):
            return fn.allocate(positions_fn(t) - shift)

    @functools.partial(jax.jit, static_argnums=(0,))
    def run_chunk(fn, temperature, nbrs, shift, start):
        def step(carry, k):
            temp, nbrs = carry
            t = dt * (start + k).astype(temp.dtype)
            positions = positions_fn(t)
            with jax.numpy_dtype_promotion("standard"):
                nbrs = fn.update(positions - shift, nbrs)
            conductance, j = neighbor_conductance(positions, radii, kappa, nbrs.idx, law, params, neck_model)
            inflow = jnp.sum(conductance * (temp[j] - temp[:, None]), axis=1)
            return (temp + dt * inflow / capacity, nbrs), None

        (temperature, nbrs), _ = jax.lax.scan(step, (temperature, nbrs), jnp.arange(chunk))
        return temperature, nbrs

    nbrs = allocate(0.0)
    reallocations = 0
    step = 0
    temperature = jnp.asarray(temperature)
    while step < n_steps:
        new_temperature, new_nbrs = run_chunk(fn, temperature, nbrs, shift, step)
        if bool(new_nbrs.did_buffer_overflow):
            # redo the chunk from its saved state, with a list sized for its end
            nbrs = allocate(max(step + chunk, 0) * dt)
            reallocations += 1
            if reallocations > 100:
                raise RuntimeError("neighbour list keeps overflowing; raise capacity_multiplier")
            continue
        temperature, nbrs = new_temperature, new_nbrs
        step += chunk
        allocate_check = np.asarray(positions_fn(step * dt))
        if np.any(allocate_check < lo) or np.any(allocate_check > hi):
            raise ValueError(f"particles left the neighbour-list box at t = {step * dt:.6g} s; motion too large")
    return temperature, {"reallocations": reallocations, "neighbor_capacity": int(nbrs.idx.shape[1]),
                         "final_idx": np.asarray(nbrs.idx)}
