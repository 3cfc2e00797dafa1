"""Baseline velocity-Verlet chain solvers for the benchmarks: plain NumPy and Numba.

Same physics and accuracy as `hertzchain` in the benchmark case: a striker and N beads in
Hertz contact ($F = \\kappa\\delta_+^{3/2}$), the last bead on a Hertz wall, no dissipation,
velocity Verlet with a fixed step. Inputs in SI: `mass_kg` (n_bodies,), `kappa` per contact
(n_bodies - 1,), wall stiffness per chain, striker speed per chain. Every solver records
three forces every step: contacts `rows[0]`, `rows[1]` (internal contact index, 0 = the
striker's) and the wall.

- `numpy_single`: one chain, a Python time loop with NumPy over the beads.
- `numpy_batch`: (B, n_bodies) arrays, a Python time loop with NumPy over chains and beads.
- `numba_single`: one chain, a compiled scalar loop (one core).
- `numba_batch`: the batch on the SIMD axis, (n_bodies, B) layout, blocks of 64 chains per
  thread (`prange`), each block run through all its steps while it sits in cache, the force
  sweep fused with both half kicks — the hand-tuned kernel the JAX path is measured against.
- `plain_jax_batch`: the performance notes' plain-JAX recipe: (n_bodies, B) layout, a
  `lax.scan` over blocks of `block` steps whose inner scan is fully unrolled and emits the
  three forces of every step, the batch split over the host devices with `shard_map`. What
  XLA reaches on this problem without hertzchain's generality (no maxima, no energies, no
  sensors or damping): the reference the batched path is profiled against.

Numba is optional (`pip install hertzchain[bench]`): `HAVE_NUMBA` says whether it is there.
"""

from __future__ import annotations

import functools

import numpy as np

try:
    import numba

    HAVE_NUMBA = True
except ImportError:  # pragma: no cover - depends on the environment
    numba = None
    HAVE_NUMBA = False

BLOCK_CHAINS = 64
# Steps per outer scan iteration of `plain_jax_batch` (the inner scan is fully unrolled).
PLAIN_JAX_BLOCK = 25


def _initial(mass_kg, v0):
    x = np.zeros_like(mass_kg)
    v = np.zeros_like(mass_kg)
    v[..., 0] = v0
    return x, v


def numpy_single(mass_kg, kappa, wall_kappa, v0, dt_s, n_steps, rows):
    """One chain in NumPy: returns the recorded forces (n_steps, 3), N."""
    h = 0.5 * dt_s
    x, v = _initial(np.asarray(mass_kg, float), v0)
    inv = 1.0 / mass_kg
    a = np.zeros_like(x)
    out = np.empty((n_steps, 3))
    body = np.zeros_like(x)
    for n in range(n_steps):
        v += h * a
        x += dt_s * v
        d = np.maximum(x[:-1] - x[1:], 0.0)
        f = kappa * d * np.sqrt(d)
        dw = max(x[-1], 0.0)
        fw = wall_kappa * dw * np.sqrt(dw)
        body[:] = 0.0
        body[1:] += f
        body[:-1] -= f
        body[-1] -= fw
        np.multiply(body, inv, out=a)
        v += h * a
        out[n, 0], out[n, 1], out[n, 2] = f[rows[0]], f[rows[1]], fw
    return out


def numpy_batch(mass_kg, kappa, wall_kappa, v0, dt_s, n_steps, rows):
    """B chains in NumPy, (B, n_bodies) arrays: returns forces (n_steps, 3, B), N."""
    wall_kappa = np.asarray(wall_kappa, float)
    batch = wall_kappa.shape[0]
    mass = np.broadcast_to(mass_kg, (batch, len(mass_kg)))
    h = 0.5 * dt_s
    x, v = _initial(np.array(mass), np.asarray(v0, float))
    inv = 1.0 / mass
    a = np.zeros_like(x)
    body = np.zeros_like(x)
    out = np.empty((n_steps, 3, batch))
    for n in range(n_steps):
        v += h * a
        x += dt_s * v
        d = np.maximum(x[:, :-1] - x[:, 1:], 0.0)
        f = kappa * d * np.sqrt(d)
        dw = np.maximum(x[:, -1], 0.0)
        fw = wall_kappa * dw * np.sqrt(dw)
        body[:] = 0.0
        body[:, 1:] += f
        body[:, :-1] -= f
        body[:, -1] -= fw
        np.multiply(body, inv, out=a)
        v += h * a
        out[n, 0], out[n, 1], out[n, 2] = f[:, rows[0]], f[:, rows[1]], fw
    return out


if HAVE_NUMBA:

    @numba.njit(fastmath=True, cache=False)
    def _numba_single(mass, kappa, wall_kappa, v0, dt, n_steps, r0, r1, out):
        nb = mass.shape[0]
        h = 0.5 * dt
        x = np.zeros(nb)
        v = np.zeros(nb)
        a = np.zeros(nb)
        inv = 1.0 / mass
        v[0] = v0
        for n in range(n_steps):
            for i in range(nb):
                v[i] += h * a[i]
                x[i] += dt * v[i]
            f_prev = 0.0
            for i in range(nb - 1):
                d = max(x[i] - x[i + 1], 0.0)
                f = kappa[i] * d * np.sqrt(d)
                a[i] = (f_prev - f) * inv[i]
                v[i] += h * a[i]
                if i == r0:
                    out[n, 0] = f
                if i == r1:
                    out[n, 1] = f
                f_prev = f
            dw = max(x[nb - 1], 0.0)
            fw = wall_kappa * dw * np.sqrt(dw)
            a[nb - 1] = (f_prev - fw) * inv[nb - 1]
            v[nb - 1] += h * a[nb - 1]
            out[n, 2] = fw

    @numba.njit(fastmath=True, parallel=True, cache=False)
    def _numba_batch(mass, kappa, wall_kappa, v0, dt, n_steps, r0, r1, out):
        nb = mass.shape[0]
        batch = wall_kappa.shape[0]
        h = 0.5 * dt
        n_blocks = (batch + BLOCK_CHAINS - 1) // BLOCK_CHAINS
        for blk in numba.prange(n_blocks):
            lo = blk * BLOCK_CHAINS
            w = min(BLOCK_CHAINS, batch - lo)
            x = np.zeros((nb, w))
            v = np.zeros((nb, w))
            a = np.zeros((nb, w))
            f_prev = np.zeros(w)
            kw = wall_kappa[lo : lo + w].copy()
            for j in range(w):
                v[0, j] = v0[lo + j]
            inv = 1.0 / mass
            for n in range(n_steps):
                for i in range(nb):
                    for j in range(w):
                        v[i, j] += h * a[i, j]
                        x[i, j] += dt * v[i, j]
                for j in range(w):
                    f_prev[j] = 0.0
                for i in range(nb - 1):
                    k = kappa[i]
                    m = inv[i]
                    for j in range(w):
                        d = max(x[i, j] - x[i + 1, j], 0.0)
                        f = k * d * np.sqrt(d)
                        a[i, j] = (f_prev[j] - f) * m
                        v[i, j] += h * a[i, j]
                        f_prev[j] = f
                    if i == r0:
                        for j in range(w):
                            out[n, 0, lo + j] = f_prev[j]
                    if i == r1:
                        for j in range(w):
                            out[n, 1, lo + j] = f_prev[j]
                m = inv[nb - 1]
                for j in range(w):
                    dw = max(x[nb - 1, j], 0.0)
                    fw = kw[j] * dw * np.sqrt(dw)
                    a[nb - 1, j] = (f_prev[j] - fw) * m
                    v[nb - 1, j] += h * a[nb - 1, j]
                    out[n, 2, lo + j] = fw


def numba_single(mass_kg, kappa, wall_kappa, v0, dt_s, n_steps, rows):
    """One chain, compiled with Numba: returns forces (n_steps, 3), N."""
    out = np.empty((n_steps, 3))
    _numba_single(
        np.asarray(mass_kg, float), np.asarray(kappa, float), float(wall_kappa), float(v0),
        float(dt_s), int(n_steps), int(rows[0]), int(rows[1]), out,
    )
    return out


def numba_batch(mass_kg, kappa, wall_kappa, v0, dt_s, n_steps, rows):
    """B chains, batch on the SIMD axis, compiled with Numba: forces (n_steps, 3, B), N."""
    wall_kappa = np.ascontiguousarray(wall_kappa, float)
    out = np.empty((n_steps, 3, wall_kappa.shape[0]))
    _numba_batch(
        np.asarray(mass_kg, float), np.asarray(kappa, float), wall_kappa,
        np.ascontiguousarray(v0, float), float(dt_s), int(n_steps), int(rows[0]), int(rows[1]), out,
    )
    return out


def plain_jax_batch(mass_kg, kappa, wall_kappa, v0, dt_s, n_steps, rows, block=PLAIN_JAX_BLOCK, devices=None,
                    to_numpy=True):
    """B chains in plain JAX, (n_bodies, B) layout, sharded over `devices` (default: all
    devices when B divides among them): forces (n_steps, 3, B), N (a NumPy array, or with
    `to_numpy=False` the JAX array as computed). Compiled once per problem shape (the
    compiled function is cached on its static arguments)."""
    import jax

    devices = tuple(jax.devices()) if devices is None else tuple(devices)
    if len(wall_kappa) % len(devices):
        devices = devices[:1]
    run = _plain_jax_compiled(int(n_steps), int(block), tuple(int(r) for r in rows), float(dt_s), devices)
    out = run(np.asarray(mass_kg, float), np.asarray(kappa, float), np.asarray(wall_kappa, float),
              np.asarray(v0, float))
    return np.asarray(out) if to_numpy else out


@functools.cache
def _plain_jax_compiled(n_steps, block, rows, dt, devices):
    """The jitted `plain_jax_batch` for one problem shape."""
    import jax
    import jax.numpy as jnp
    from jax.sharding import Mesh
    from jax.sharding import PartitionSpec as P

    jax.config.update("jax_enable_x64", True)
    h = 0.5 * dt

    def local(mass, kappa, wall_kappa, v0):
        inv = (1.0 / mass)[:, None]
        k = kappa[:, None]
        x = jnp.zeros((mass.shape[0], 1)) * v0  # zeros that vary along the batch, as v0
        v = x.at[0].set(v0)

        def step(state, _):
            x, v, a = state
            v = v + h * a
            x = x + dt * v
            d = jnp.maximum(x[:-1] - x[1:], 0.0)
            f = k * d * jnp.sqrt(d)
            dw = jnp.maximum(x[-1:], 0.0)
            fw = wall_kappa * dw * jnp.sqrt(dw)
            zero = jnp.zeros_like(fw)
            a = (jnp.concatenate([zero, f]) - jnp.concatenate([f, fw])) * inv
            v = v + h * a
            return (x, v, a), jnp.concatenate([f[rows[0] : rows[0] + 1], f[rows[1] : rows[1] + 1], fw])

        def outer(state, _):
            return jax.lax.scan(step, state, None, length=block, unroll=block)

        state, out = jax.lax.scan(outer, (x, v, jnp.zeros_like(x)), None, length=n_steps // block)
        out = out.reshape(-1, 3, v0.shape[0])
        if n_steps % block:
            out = jnp.concatenate([out, jax.lax.scan(step, state, None, length=n_steps % block)[1]])
        return out

    if len(devices) > 1:
        mesh = Mesh(np.asarray(devices), ("batch",))
        local = jax.shard_map(local, mesh=mesh, in_specs=(P(), P(), P("batch"), P("batch")),
                              out_specs=P(None, None, "batch"))
    return jax.jit(local)
