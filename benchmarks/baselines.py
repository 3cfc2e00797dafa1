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
        # One block of BLOCK_CHAINS chains per task (the batch is padded to whole blocks),
        # all steps in cache; one sweep per step: the drift of body i + 1, the force of
        # contact i, the kick of body i. u = v + (dt/2) a is the next drift's velocity.
        nb = mass.shape[0]
        n_blocks = wall_kappa.shape[0] // BLOCK_CHAINS
        inv = 1.0 / mass
        for blk in numba.prange(n_blocks):
            lo = blk * BLOCK_CHAINS
            x = np.zeros((nb, BLOCK_CHAINS))
            u = np.zeros((nb, BLOCK_CHAINS))
            f_prev = np.zeros(BLOCK_CHAINS)
            kw = wall_kappa[lo : lo + BLOCK_CHAINS].copy()
            for j in range(BLOCK_CHAINS):
                u[0, j] = v0[lo + j]  # a = 0 at the impact
            for n in range(n_steps):
                for j in range(BLOCK_CHAINS):
                    x[0, j] += dt * u[0, j]
                    f_prev[j] = 0.0
                for i in range(nb - 1):
                    k = kappa[i]
                    m = dt * inv[i]
                    for j in range(BLOCK_CHAINS):
                        x[i + 1, j] += dt * u[i + 1, j]
                        d = max(x[i, j] - x[i + 1, j], 0.0)
                        f = k * d * np.sqrt(d)
                        u[i, j] += (f_prev[j] - f) * m
                        f_prev[j] = f
                m = dt * inv[nb - 1]
                for j in range(BLOCK_CHAINS):
                    dw = max(x[nb - 1, j], 0.0)
                    fw = kw[j] * dw * np.sqrt(dw)
                    u[nb - 1, j] += (f_prev[j] - fw) * m
                    d0 = max(x[r0, j] - x[r0 + 1, j], 0.0)
                    d1 = max(x[r1, j] - x[r1 + 1, j], 0.0)
                    out[n, 0, lo + j] = kappa[r0] * d0 * np.sqrt(d0)
                    out[n, 1, lo + j] = kappa[r1] * d1 * np.sqrt(d1)
                    out[n, 2, lo + j] = fw

    @numba.njit(fastmath=True, inline="always")
    def _kick(w, loss):
        # contact.track_friction_kick: sign(w) max(|w| - mu g dt/2, 0)
        s = abs(w) - loss
        return 0.0 if s <= 0.0 else (s if w > 0.0 else -s)

    @numba.njit(fastmath=True, inline="always")
    def _damped_force(d, rate, k, c):
        # contact.contact_force: Hertz plus Kuwabara-Kono (3/2) eta kappa sqrt(delta) rate, clipped at 0
        if d <= 0.0:
            return 0.0
        r = np.sqrt(d)
        return max(k * d * r + c * k * r * rate, 0.0)

    @numba.njit(fastmath=True, parallel=True, cache=False)
    def _numba_damped_batch(mass, kappa, wall_kappa, v0, eta, decel, dt, n_steps, r0, r1, out):
        # The damped, frictional step of hertzchain (integrate.verlet_step): half kick,
        # friction kick, drift, forces at the predicted velocities v_half + (dt/2) a, half
        # kick, friction kick; blocks of BLOCK_CHAINS chains, one sweep per step (the drift
        # of body i + 1, the force of contact i, the second half kick of body i). The
        # recorded forces are taken at the step's final velocities, as hertzchain records them.
        nb = mass.shape[0]
        n_blocks = wall_kappa.shape[0] // BLOCK_CHAINS
        inv = 1.0 / mass
        h = 0.5 * dt
        loss = decel * h
        c = 1.5 * eta
        for blk in numba.prange(n_blocks):
            lo = blk * BLOCK_CHAINS
            x = np.zeros((nb, BLOCK_CHAINS))
            v = np.zeros((nb, BLOCK_CHAINS))
            a = np.zeros((nb, BLOCK_CHAINS))
            f_prev = np.zeros(BLOCK_CHAINS)
            p_prev = np.zeros(BLOCK_CHAINS)  # predicted velocity of body i
            w_prev = np.zeros(BLOCK_CHAINS)  # friction-kicked half-step velocity of body i
            kw = wall_kappa[lo : lo + BLOCK_CHAINS].copy()
            for j in range(BLOCK_CHAINS):
                v[0, j] = v0[lo + j]
            for n in range(n_steps):
                for j in range(BLOCK_CHAINS):
                    w = _kick(v[0, j] + h * a[0, j], loss)
                    x[0, j] += dt * w
                    p_prev[j] = w + h * a[0, j]
                    w_prev[j] = w
                    f_prev[j] = 0.0
                for i in range(nb - 1):
                    k = kappa[i]
                    m = inv[i]
                    for j in range(BLOCK_CHAINS):
                        w = _kick(v[i + 1, j] + h * a[i + 1, j], loss)
                        x[i + 1, j] += dt * w
                        p = w + h * a[i + 1, j]
                        f = _damped_force(x[i, j] - x[i + 1, j], p_prev[j] - p, k, c)
                        acc = (f_prev[j] - f) * m
                        a[i, j] = acc
                        v[i, j] = _kick(w_prev[j] + h * acc, loss)
                        f_prev[j] = f
                        p_prev[j] = p
                        w_prev[j] = w
                m = inv[nb - 1]
                for j in range(BLOCK_CHAINS):
                    fw = _damped_force(x[nb - 1, j], p_prev[j], kw[j], c)
                    acc = (f_prev[j] - fw) * m
                    a[nb - 1, j] = acc
                    v[nb - 1, j] = _kick(w_prev[j] + h * acc, loss)
                for j in range(BLOCK_CHAINS):
                    out[n, 0, lo + j] = _damped_force(x[r0, j] - x[r0 + 1, j], v[r0, j] - v[r0 + 1, j], kappa[r0], c)
                    out[n, 1, lo + j] = _damped_force(x[r1, j] - x[r1 + 1, j], v[r1, j] - v[r1 + 1, j], kappa[r1], c)
                    out[n, 2, lo + j] = _damped_force(x[nb - 1, j], v[nb - 1, j], kw[j], c)


def _padded(values, batch):
    """`values` (B,) extended to `batch` entries by repeating the last (whole blocks)."""
    values = np.ascontiguousarray(values, float)
    return np.concatenate([values, np.repeat(values[-1:], batch - values.shape[0])])


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
    batch = len(wall_kappa)
    padded = BLOCK_CHAINS * -(-batch // BLOCK_CHAINS)
    out = np.empty((n_steps, 3, padded))
    _numba_batch(
        np.asarray(mass_kg, float), np.asarray(kappa, float), _padded(wall_kappa, padded), _padded(v0, padded),
        float(dt_s), int(n_steps), int(rows[0]), int(rows[1]), out,
    )
    return out[:, :, :batch]


def numba_damped_batch(mass_kg, kappa, wall_kappa, v0, dt_s, n_steps, rows, *, eta_s, friction_decel_m_s2):
    """`numba_batch` with Kuwabara-Kono damping (`eta_s`, s) at every contact, wall
    included, the total force clipped at 0, and track friction of deceleration
    `friction_decel_m_s2` (= mu g, m/s^2) on every body: forces (n_steps, 3, B), N."""
    batch = len(wall_kappa)
    padded = BLOCK_CHAINS * -(-batch // BLOCK_CHAINS)
    out = np.empty((n_steps, 3, padded))
    _numba_damped_batch(
        np.asarray(mass_kg, float), np.asarray(kappa, float), _padded(wall_kappa, padded), _padded(v0, padded),
        float(eta_s), float(friction_decel_m_s2), float(dt_s), int(n_steps), int(rows[0]), int(rows[1]), out,
    )
    return out[:, :, :batch]


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
