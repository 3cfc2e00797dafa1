"""Synthetic trace files with known truth, for tests, benchmarks and coverage studies.

The traces are simulated with a finer time step than fits use (`steps_per_contact=800`
against 400, 80 steps per half period of an embedded sensor against 40) so that a fit does not share the data's discretisation, then shifted by a
trigger offset, scaled by channel gains, and given white Gaussian noise.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from hertzchain.chain import ChainSetup
from hertzchain.integrate import Recording, solve_stacked, stack_setups
from hertzchain.io.tracefile import TraceFile, setup_header
from hertzchain.timegrid import choose_time_grid

from .model import SENSOR_STEPS_PER_HALF_PERIOD, interpolate, time_step_s

DATA_STEPS_PER_CONTACT = 800


def simulate_clean(setups, *, contacts=(), t_end_s: float, sample_interval_s: float,
                   steps_per_contact: int = DATA_STEPS_PER_CONTACT) -> list[dict]:
    """Noise-free channels of several setups of one structure (one vmapped run), per setup."""
    stacked = stack_setups(setups)
    dt = time_step_s(stacked, sample_interval_s, steps_per_contact=steps_per_contact,
                     sensor_steps=2 * SENSOR_STEPS_PER_HALF_PERIOD)
    grid = choose_time_grid(stacked, t_end_s=t_end_s, sample_interval_s=sample_interval_s, dt_s=dt)
    recording = Recording(contacts=tuple(contacts))
    traces = solve_stacked(stacked, grid, recording)
    out = []
    for b in range(len(setups)):
        channels = {name: np.asarray(traces.forces_n[name][b]) for name in traces.channel_names}
        out.append(channels)
    return out


def sampled_clean(setups, *, contacts=(), t_end_s: float, sample_interval_s: float,
                  time_offset_s=0.0, fine_factor: int = 4) -> tuple[np.ndarray, list[dict]]:
    """Noise-free channels of `setups` on the data's time axis, as a recording shifted by a
    trigger offset sees them.

    The setups are simulated `fine_factor` times finer than `sample_interval_s` (with
    `simulate_clean`), and each channel, preceded by its value before the impact (the
    preload), is interpolated at $(t - t_{off})$ for the data times
    $t = k \\cdot$ `sample_interval_s`, k = 1 .. `t_end_s`/`sample_interval_s`.

    **Returns:** the data times (n,) and, per setup, a dict channel -> (n,) force, N.
    """
    offsets = np.broadcast_to(np.asarray(time_offset_s, dtype=float), (len(setups),))
    fine = sample_interval_s / fine_factor
    margin = float(np.max(np.abs(offsets))) + 4 * sample_interval_s
    clean = simulate_clean(setups, contacts=contacts, t_end_s=t_end_s + margin, sample_interval_s=fine)
    time = sample_interval_s * np.arange(1, round(t_end_s / sample_interval_s) + 1)
    sampled = []
    for b, setup in enumerate(setups):
        channels = {}
        for name, series in clean[b].items():
            full = np.concatenate([[float(setup.precompression_n)], series])
            where = jnp.asarray((time - offsets[b]) / fine)
            channels[name] = np.asarray(interpolate(jnp.asarray(full), where))
        sampled.append(channels)
    return time, sampled


def synthetic_traces(setups, *, contacts=(), t_end_s: float = 2.5e-3, sample_interval_s: float = 1e-6,
                     noise_std_n=0.0, time_offset_s=0.0, gains=None, seed: int = 0,
                     fine_factor: int = 4, header_velocity: bool = True,
                     header_noise: bool = True) -> list[TraceFile]:
    """Trace files of `setups` (same structure) with noise, offsets and gains.

    **Arguments:**

    - `setups`: `ChainSetup`s with the same number of beads, end and sensor beads.
    - `contacts`: contacts recorded (wall and sensors are always recorded).
    - `t_end_s`, `sample_interval_s`: the data's time axis, s: samples at k * interval,
      k = 1 .. t_end/interval.
    - `noise_std_n`: standard deviation of white Gaussian noise, N (scalar or per setup).
    - `time_offset_s`: trigger offset per setup (data clock at the impact), s.
    - `gains`: per setup, dict channel -> gain (default 1).
    - `seed`: noise seed.
    - `fine_factor`: simulated sampling is this much finer than the data's, then
      interpolated to the (shifted) data times.
    - `header_velocity`, `header_noise`: write striker velocity / noise into the header.
    """
    n = len(setups)
    noise = np.broadcast_to(np.asarray(noise_std_n, dtype=float), (n,))
    offsets = np.broadcast_to(np.asarray(time_offset_s, dtype=float), (n,))
    time, clean = sampled_clean(setups, contacts=contacts, t_end_s=t_end_s,
                                sample_interval_s=sample_interval_s, time_offset_s=offsets,
                                fine_factor=fine_factor)
    rng = np.random.default_rng(seed)
    files = []
    for b, setup in enumerate(setups):
        channels = {}
        for name, value in clean[b].items():
            gain = (gains[b] if gains is not None else {}).get(name, 1.0)
            channels[name] = gain * value + noise[b] * rng.standard_normal(time.size)
        header = setup_header(setup)
        if not header_velocity:
            header.pop("striker_velocity_m_s")
        if header_noise and noise[b] > 0:
            header["noise_std_n"] = float(noise[b])
        header["x_true_eta_s"] = repr(float(setup.eta_s))
        header["x_true_mu"] = repr(float(setup.mu))
        header["x_true_mu_star"] = repr(float(setup.mu_star))
        header["x_true_striker_velocity_m_s"] = repr(float(setup.striker_velocity_m_s))
        header["x_true_time_offset_s"] = repr(float(offsets[b]))
        files.append(TraceFile(header=header, time_s=time, channels=channels, path=None))
    return files


def paper_setups(velocities_m_s, *, eta_s: float = 2e-6, mu: float = 0.19, mu_star: float = 0.0,
                 **fields) -> list[ChainSetup]:
    """The paper's chain at several impact velocities (eta 2 us, mu 0.19 by default)."""
    return [
        ChainSetup(striker_velocity_m_s=v, eta_s=eta_s, mu=mu, mu_star=mu_star, **fields)
        for v in velocities_m_s
    ]
