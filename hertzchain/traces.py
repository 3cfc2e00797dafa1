"""`Traces`: what a simulation records, sample by sample."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np


class Traces(eqx.Module):
    """Recorded observables of one run (or a batch of runs, with leading batch axes).

    Samples are taken every `sample_interval_s`, at `time_s = (i+1) * sample_interval_s`,
    time 0 being the impact. Energies are J, forces N, impulses and momenta N s.

    **Fields:**

    - `time_s`: (n_samples,).
    - `forces_n`: channel name -> (n_samples,) force, N. Names follow the trace-file format:
      `contact_K` (force between bead K and K+1, contact 0 the striker's), `wall`,
      `sensor_K` (compression of the sensor spring in bead K, in N).
    - `channel_names`: the channels in file order.
    - `kinetic_j`, `elastic_j` (all contacts and the wall), `wall_elastic_j`,
      `preload_potential_j`, `dissipated_viscous_j`, `dissipated_friction_j`,
      `dissipated_plastic_j`: the energy ledger. `energy_error_j` is the initial energy minus the sum of all of them: the
      integrator's own error (zero for an exact solution).
    - `momentum_kg_m_s`: total momentum of all bodies. `wall_impulse_n_s`,
      `friction_impulse_n_s`, `preload_impulse_n_s`: impulse given to the chain's momentum
      balance since the impact (wall's taken positive when it pushes the chain back;
      the balance is momentum = initial - wall + friction + preload).
    - `initial_energy_j`, `initial_momentum_kg_m_s`: scalars.
    - `max_force_n`: the largest force reached at contacts 0..N-1 and at the wall (last),
      over every step of the run.
    - `yield_force_n`: the yield force of the same contacts (paper's estimate).
    - `contact_forces_n`, `contact_elastic_j`: (n_samples, N) for every contact 0..N-1, and
      `positions_m`, `velocities_m_s`: (n_samples, n_bodies) displacement from the initial
      position and velocity of every body (striker, beads; sensor beads as two halves);
      only when the run was asked to record everything, otherwise None.
    """

    time_s: jax.Array
    forces_n: dict[str, jax.Array]
    kinetic_j: jax.Array
    elastic_j: jax.Array
    wall_elastic_j: jax.Array
    preload_potential_j: jax.Array
    dissipated_viscous_j: jax.Array
    dissipated_friction_j: jax.Array
    dissipated_plastic_j: jax.Array
    energy_error_j: jax.Array
    momentum_kg_m_s: jax.Array
    wall_impulse_n_s: jax.Array
    friction_impulse_n_s: jax.Array
    preload_impulse_n_s: jax.Array
    initial_energy_j: jax.Array
    initial_momentum_kg_m_s: jax.Array
    max_force_n: jax.Array
    yield_force_n: jax.Array
    contact_forces_n: jax.Array | None = None
    contact_elastic_j: jax.Array | None = None
    positions_m: jax.Array | None = None
    velocities_m_s: jax.Array | None = None
    channel_names: tuple[str, ...] = eqx.field(static=True, default=())

    def force(self, channel: str) -> jax.Array:
        """The force trace of one channel, N; raises with the recorded names if absent."""
        if channel not in self.forces_n:
            raise KeyError(
                f"Channel {channel!r} was not recorded; recorded: {', '.join(self.channel_names)}."
            )
        return self.forces_n[channel]

    @property
    def potential_j(self) -> jax.Array:
        """Elastic plus preload potential energy, J."""
        return self.elastic_j + self.preload_potential_j

    @property
    def mechanical_energy_j(self) -> jax.Array:
        """Kinetic plus potential energy, J."""
        return self.kinetic_j + self.potential_j

    @property
    def dissipated_j(self) -> jax.Array:
        """Energy dissipated by all mechanisms since the impact, J."""
        return self.dissipated_viscous_j + self.dissipated_friction_j + self.dissipated_plastic_j

    @property
    def momentum_balance_error_kg_m_s(self) -> jax.Array:
        """Momentum minus what the impulses of the wall, friction and preload explain."""
        expected = (
            self.initial_momentum_kg_m_s[..., None]
            - self.wall_impulse_n_s
            + self.friction_impulse_n_s
            + self.preload_impulse_n_s
        )
        return self.momentum_kg_m_s - expected

    def to_numpy(self) -> dict[str, np.ndarray]:
        """Columns of the time series as NumPy arrays (time, forces in channel order, ledger)."""
        columns = {"time_s": np.asarray(self.time_s)}
        for name in self.channel_names:
            columns[name] = np.asarray(self.forces_n[name])
        for name in (
            "kinetic_j",
            "elastic_j",
            "wall_elastic_j",
            "preload_potential_j",
            "dissipated_viscous_j",
            "dissipated_friction_j",
            "dissipated_plastic_j",
            "energy_error_j",
            "momentum_kg_m_s",
            "wall_impulse_n_s",
            "friction_impulse_n_s",
            "preload_impulse_n_s",
        ):
            columns[name] = np.asarray(getattr(self, name))
        return columns


def stack_channels(traces: Traces, channels=None) -> jax.Array:
    """Forces of `channels` (default: all, in file order) as an (..., n_samples, n_channels) array."""
    names = traces.channel_names if channels is None else tuple(channels)
    return jnp.stack([traces.force(name) for name in names], axis=-1)
