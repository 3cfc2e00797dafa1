"""The lock-in response of a driven chain over a frequency × drive-amplitude grid.

    lockin_grid(chain, frequencies_hz, drive_amplitudes_m, *, bead=1, quantity="velocity",
                harmonics=(1.0, 0.5), ramp_periods=25, hold_periods=35, window_periods=4,
                steps_per_period=64, unroll=8) -> LockinGrid

Every (f, a) pair is one run: the chain starts at rest in its static equilibrium, the
driver's amplitude rises from 0 to a over `ramp_periods` periods (`drive.smooth_step`) and
holds for `hold_periods` more; the lock-in reads the chosen bead's velocity (or
displacement) over the last `window_periods` whole periods of the hold, at each harmonic
(× f) in `harmonics`. The smooth ramp lands on the branch an upward amplitude sweep
follows. All F × A runs advance together as one batch on the SIMD axis of one `lax.scan`
(`kernel`), each run with its own step $1/(f N)$, $N$ = `steps_per_period`: the same number
of steps per period in every run, the same phase $2\\pi j/N$ at step j. Forward-mode
derivatives (`jax.jacfwd`, `jax.jvp`) go through everything, with respect to the chain's
fields and the drive amplitudes (and the frequencies).

Accuracy: velocity-Verlet shifts a linear resonance by about $(2\\pi/N)^2/24$ of its
frequency (4e-4 at N = 64), and a transient decays as $e^{-\\gamma t/2}$: over the hold it
falls by $e^{-\\gamma H/(2f)}$ (`settle_periods` gives the hold for a tolerance).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import drive as drives
from . import kernel
from .chain import DrivenChain
from .lockin import lockin_steps

QUANTITIES = ("velocity", "displacement")
# The largest (highest linear mode's angular frequency × step) accepted: velocity-Verlet is
# stable below 2, and accurate to about (omega dt)^2 / 24 of the mode's frequency.
MAX_OMEGA_DT = 1.0


class LockinGrid(eqx.Module):
    """What `lockin_grid` returns.

    **Fields:**

    - `rms`: (n_harmonics, F, A) lock-in RMS of the bead's velocity (m/s) or displacement
      (m) at each harmonic of each drive frequency, for each drive amplitude.
    - `phase_rad`: (n_harmonics, F, A) its phase against the drive $\\cos(2\\pi f t)$, rad.
    - `complex_amplitude`: (n_harmonics, F, A) $A e^{i\\varphi}$ ($A = \\sqrt2$ RMS).
    - `frequencies_hz` (F,), `drive_amplitudes_m` (A,): the grid.
    - `harmonics`, `quantity`, `bead`: what was demodulated (static).
    """

    complex_amplitude: jax.Array
    frequencies_hz: jax.Array
    drive_amplitudes_m: jax.Array
    harmonics: tuple[float, ...] = eqx.field(static=True)
    quantity: str = eqx.field(static=True)
    bead: int = eqx.field(static=True)

    @property
    def rms(self) -> jax.Array:
        return jnp.abs(self.complex_amplitude) / jnp.sqrt(2.0)

    @property
    def phase_rad(self) -> jax.Array:
        return jnp.angle(self.complex_amplitude)


def lockin_grid(
    chain: DrivenChain,
    frequencies_hz,
    drive_amplitudes_m,
    *,
    bead: int = 1,
    quantity: str = "velocity",
    harmonics: tuple[float, ...] = (1.0, 0.5),
    ramp_periods: int = 25,
    hold_periods: int = 35,
    window_periods: int = 4,
    steps_per_period: int = 64,
    unroll: int = kernel.DEFAULT_UNROLL,
) -> LockinGrid:
    """Lock-in response of `chain` over the grid `frequencies_hz` (F,) × `drive_amplitudes_m`
    (A,) (the driver's displacement amplitude, m, ≥ 0), all F × A runs as one batch.

    **Arguments:**

    - `chain`: the `DrivenChain` (may be traced: `jax.jacfwd(lambda c: lockin_grid(c, ...).rms)`).
    - `frequencies_hz`: (F,) drive frequencies, Hz (> 0).
    - `drive_amplitudes_m`: (A,) drive displacement amplitudes, m.
    - `bead`: which bead the vibrometer reads, 1..n (1 = next to the driver).
    - `quantity`: "velocity" (m/s) or "displacement" (m, from the static equilibrium).
    - `harmonics`: multiples of f to demodulate (1.0 = the drive's, 0.5 = the subharmonic);
      `window_periods` × each must be whole (e.g. an even window for 0.5).
    - `ramp_periods`, `hold_periods`: periods of the amplitude ramp from 0 and of the hold
      after it; `window_periods` (≤ `hold_periods`): the last periods, read by the lock-in.
    - `steps_per_period`: velocity-Verlet steps per drive period N (each run's step is
      1/(f N)); checked against the chain's highest linear mode (ω dt ≤ 1).
    - `unroll`: steps per scan iteration (speed only).

    **Returns:** `LockinGrid` with `.rms` and `.phase_rad` of shape (n_harmonics, F, A).
    """
    harmonics = tuple(float(h) for h in harmonics)
    _check_arguments(chain, frequencies_hz, drive_amplitudes_m, bead, quantity, harmonics, ramp_periods,
                     hold_periods, window_periods, steps_per_period)
    return _lockin_grid(chain, jnp.asarray(frequencies_hz, dtype=jnp.float64),
                        jnp.asarray(drive_amplitudes_m, dtype=jnp.float64), int(bead), quantity, harmonics,
                        int(ramp_periods), int(hold_periods), int(window_periods), int(steps_per_period), int(unroll))


@eqx.filter_jit
def _lockin_grid(chain, frequencies_hz, drive_amplitudes_m, bead, quantity, harmonics, ramp_periods,
                 hold_periods, window_periods, steps_per_period, unroll):
    n_freq, n_amp = frequencies_hz.shape[0], drive_amplitudes_m.shape[0]
    frequency = jnp.repeat(frequencies_hz, n_amp)  # run index = i_f * A + i_a
    amplitude = jnp.tile(drive_amplitudes_m, n_freq)
    readings = run_harmonic(chain, frequency, amplitude, bead=bead, quantity=quantity, harmonics=harmonics,
                            ramp_periods=ramp_periods, hold_periods=hold_periods, window_periods=window_periods,
                            steps_per_period=steps_per_period, unroll=unroll)
    return LockinGrid(
        complex_amplitude=readings.reshape(len(harmonics), n_freq, n_amp),
        frequencies_hz=frequencies_hz,
        drive_amplitudes_m=drive_amplitudes_m,
        harmonics=harmonics,
        quantity=quantity,
        bead=bead,
    )


def run_harmonic(chain, frequency_hz, amplitude_m, *, bead, quantity, harmonics, ramp_periods, hold_periods,
                 window_periods, steps_per_period, unroll=kernel.DEFAULT_UNROLL, state=None):
    """The runs of `lockin_grid`, given run by run: `frequency_hz`, `amplitude_m` (B,).
    **Returns:** (n_harmonics, B) complex amplitudes (traceable; arguments as `lockin_grid`'s,
    already checked). With `state` (a `kernel.State` of B runs), start there and drive at
    full amplitude at once instead of from rest with a ramp (`ramp_periods` must be 0)."""
    p = kernel.kernel_params(chain)
    n = steps_per_period
    dt = 1.0 / (frequency_hz * n)
    batch = frequency_hz.shape[0]
    if state is None:
        state = kernel.static_state(p, batch)
    drive = drives.harmonic_segment(frequency_hz, dt, n, 0.0 * amplitude_m, amplitude_m, ramp_periods * n)
    settle = (ramp_periods + hold_periods - window_periods) * n
    state, _ = kernel.advance(p, state, dt, drive, jnp.arange(1, settle + 1), unroll=unroll)
    row = bead - 1
    if quantity == "velocity":
        def record(s, u, u_dot):
            return s.velocity_m_s[row]
    else:
        def record(s, u, u_dot):
            return s.displacement_m[row]
    first = settle + 1
    _, samples = kernel.advance(p, state, dt, drive, jnp.arange(first, first + window_periods * n), record=record,
                                unroll=unroll)
    return jnp.stack([lockin_steps(samples, n, h, first).complex_amplitude for h in harmonics])


def settle_periods(chain: DrivenChain, frequency_hz: float, tolerance: float = 1e-4) -> int:
    """Periods of `frequency_hz` after which a transient of the least damped bead has decayed
    to `tolerance` of its start, $\\lceil 2\\ln(1/\\mathrm{tol})\\,f/\\gamma_{\\min}\\rceil$ (the
    envelope of a viscously damped oscillation falls as $e^{-\\gamma t/2}$). Concrete inputs."""
    rate = float(np.min(np.asarray(chain.damping_rate_per_s)))
    if rate <= 0.0:
        raise ValueError("settle_periods: a chain without damping (damping_rate_per_s = 0) never settles.")
    return int(np.ceil(2.0 * np.log(1.0 / tolerance) * float(frequency_hz) / rate))


def _check_arguments(chain, frequencies_hz, drive_amplitudes_m, bead, quantity, harmonics, ramp_periods,
                     hold_periods, window_periods, steps_per_period) -> None:
    if not isinstance(chain, DrivenChain):
        raise ValueError(f"chain: expected a DrivenChain, got {type(chain).__name__}.")
    if quantity not in QUANTITIES:
        raise ValueError(f"quantity: expected one of {QUANTITIES}, got {quantity!r}.")
    if int(bead) != bead or not 1 <= bead <= chain.n_beads:
        raise ValueError(f"bead: beads are numbered 1..{chain.n_beads} from the driver, got {bead}.")
    for name, value in (("ramp_periods", ramp_periods), ("hold_periods", hold_periods),
                        ("window_periods", window_periods), ("steps_per_period", steps_per_period)):
        if int(value) != value or value < 0:
            raise ValueError(f"{name}: expected a whole number of periods/steps >= 0, got {value}.")
    if window_periods < 1 or window_periods > hold_periods:
        raise ValueError(f"window_periods: must be 1..hold_periods ({hold_periods}), got {window_periods}.")
    if steps_per_period < 8:
        raise ValueError(f"steps_per_period: at least 8 steps per drive period, got {steps_per_period}.")
    if not harmonics:
        raise ValueError("harmonics: give at least one multiple of the drive frequency, e.g. (1.0, 0.5).")
    for h in harmonics:
        if h <= 0 or abs(h * window_periods - round(h * window_periods)) > 1e-9:
            raise ValueError(
                f"harmonics: {h} × window_periods ({window_periods}) must be a whole number of periods of "
                f"the demodulated component (h > 0); e.g. an even window for h = 0.5."
            )
        if h * 2 >= steps_per_period:
            raise ValueError(f"harmonics: {h} × f is above the Nyquist frequency of {steps_per_period} steps a period.")
    for name, values, unit in (("frequencies_hz", frequencies_hz, "Hz"), ("drive_amplitudes_m", drive_amplitudes_m, "m")):
        if isinstance(values, jax.core.Tracer):
            continue
        array = np.asarray(values, dtype=float)
        if array.ndim != 1 or array.size == 0:
            raise ValueError(f"{name}: expected a non-empty 1-D array ({unit}), got shape {array.shape}.")
        if not np.all(np.isfinite(array)) or (name == "frequencies_hz" and np.any(array <= 0)) or np.any(array < 0):
            raise ValueError(f"{name}: values must be finite and {'> 0' if name == 'frequencies_hz' else '>= 0'} "
                             f"({unit}), got {array}.")
    traced = [leaf for leaf in jax.tree_util.tree_leaves((chain, frequencies_hz)) if isinstance(leaf, jax.core.Tracer)]
    if not traced:
        omega_dt = 2.0 * np.pi * float(chain.highest_frequency_bound_hz()) / (
            float(np.min(np.asarray(frequencies_hz))) * steps_per_period)
        if omega_dt > MAX_OMEGA_DT:
            needed = int(np.ceil(steps_per_period * omega_dt / MAX_OMEGA_DT))
            raise ValueError(
                f"steps_per_period: {steps_per_period} steps per period of the lowest frequency "
                f"({float(np.min(np.asarray(frequencies_hz))):.6g} Hz) under-resolve the chain's highest mode "
                f"(ω dt = {omega_dt:.3g} > {MAX_OMEGA_DT}); use steps_per_period >= {needed}."
            )
