"""The lock-in response of a driven chain over a frequency × drive-amplitude grid.

    lockin_grid(chain, frequencies_hz, drive_amplitudes_m, *, bead=1, quantity="velocity",
                harmonics=(1.0, 0.5), ramp_periods=25, hold_periods=35, window_periods=4,
                steps_per_period=64, contact=None, unroll=8) -> LockinGrid
    LockinGrid: .rms, .phase_rad, .complex_amplitude (n_harmonics, F, A); .frequencies_hz,
                .drive_amplitudes_m; static .harmonics, .quantity, .bead, .contact

Every (f, a) pair is one run: the chain starts at rest in its static equilibrium, the
driver's amplitude rises from 0 to a over `ramp_periods` periods (`drive.smooth_step`) and
holds for `hold_periods` more; the lock-in reads the chosen bead's velocity (or
displacement, or a contact's force) over the last `window_periods` whole periods of the
hold, at each harmonic (× f) in `harmonics`. All F × A runs advance together as one batch
on the SIMD axis of one `lax.scan` (`kernel`), each run with its own step $1/(f N)$, $N$ = `steps_per_period`: the same number
of steps per period in every run, the same phase $2\\pi j/N$ at step j. Forward-mode
derivatives (`jax.jacfwd`, `jax.jvp`) go through everything, with respect to the chain's
fields and the drive amplitudes (and the frequencies).

Accuracy: velocity-Verlet shifts a linear resonance by about $(2\\pi/N)^2/24$ of its
frequency (4e-4 at N = 64), and a transient decays as $e^{-\\gamma t/2}$: over the hold it
falls by $e^{-\\gamma H/(2f)}$ (`settle_periods` gives the hold for a tolerance).

Which branch: where the response is bistable, the ramp (the amplitude rising at a fixed
frequency) ends on the branch that path reaches. In the single-bead regime of Lydon et al.
that is the branch of a phase-continuous upward frequency sweep, and it stays so through a
bistable window at lighter damping (tests: ζ ≈ 0.036, and γ = 400 /s); at lighter damping
still (γ = 250 /s) part of the window ends on the resonant branch instead, however slow the
ramp. A sweep up with `lockin_schedule` follows the upward branch by construction.

Period doubling: without noise, a subharmonic grows only from what the ramp leaves at
f/2, at the rate set by the Floquet multiplier (`floquet_multipliers`): just past a
threshold it may not show within the hold. `period_doubling_threshold` finds the
threshold itself.
"""

from __future__ import annotations

import inspect

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import fused
from .chain import DrivenChain
from .kernel import DEFAULT_UNROLL, kernel_params
from .lockin import AbstractReading
from .schedule import HarmonicSchedule, check_readout, lockin_levels


class LockinGrid(AbstractReading):
    """What `lockin_grid` returns.

    **Fields:**

    - `rms`: (n_harmonics, F, A) lock-in RMS of the bead's velocity (m/s) or displacement
      (m), or of the contact's force (N), at each harmonic of each drive frequency, for each
      drive amplitude.
    - `phase_rad`: (n_harmonics, F, A) its phase against the drive $\\cos(2\\pi f t)$, rad.
    - `complex_amplitude`: (n_harmonics, F, A) $A e^{i\\varphi}$ ($A = \\sqrt2$ RMS).
    - `frequencies_hz` (F,), `drive_amplitudes_m` (A,): the grid.
    - `harmonics`, `quantity`, `bead`, `contact`: what was demodulated (static).
    - `kernel`: which kernel ran (static): "fused" (`hertzchain.driven.fused`) or "jax";
      None where it was not recorded (a grid read back from a sweep folder).
    """

    complex_amplitude: jax.Array
    frequencies_hz: jax.Array
    drive_amplitudes_m: jax.Array
    harmonics: tuple[float, ...] = eqx.field(static=True)
    quantity: str = eqx.field(static=True)
    bead: int = eqx.field(static=True)
    contact: int | None = eqx.field(static=True, default=None)
    kernel: str | None = eqx.field(static=True, default=None)


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
    contact: int | None = None,
    unroll: int = DEFAULT_UNROLL,
    kernel: str = "auto",
) -> LockinGrid:
    """Lock-in response of `chain` over the grid `frequencies_hz` (F,) × `drive_amplitudes_m`
    (A,) (the driver's displacement amplitude, m, ≥ 0), all F × A runs as one batch.

    **Arguments:**

    - `chain`: the `DrivenChain` (may be traced: `jax.jacfwd(lambda c: lockin_grid(c, ...).rms)`).
    - `frequencies_hz`: (F,) drive frequencies, Hz (> 0).
    - `drive_amplitudes_m`: (A,) drive displacement amplitudes, m.
    - `bead`: which bead the vibrometer reads, 1..n (1 = next to the driver).
    - `quantity`: "velocity" (m/s) or "displacement" (m, from the static equilibrium) of
      `bead`, or "force" (N) of `contact`.
    - `harmonics`: multiples of f to demodulate (1.0 = the drive's, 0.5 = the subharmonic);
      `window_periods` × each must be whole (e.g. an even window for 0.5).
    - `ramp_periods`, `hold_periods`: periods of the amplitude ramp from 0 and of the hold
      after it; `window_periods` (≤ `hold_periods`): the last periods, read by the lock-in.
    - `steps_per_period`: velocity-Verlet steps per drive period N (each run's step is
      1/(f N)); checked against the chain's highest linear mode (ω dt ≤ 1).
    - `contact`: with `quantity="force"`, the contact whose total force the lock-in reads
      (0 = driver face .. n = wall; N), as a force sensor there would.
    - `unroll`: steps per scan iteration of the JAX kernel (speed only).
    - `kernel`: "auto" (default) runs the fused host kernel (`hertzchain.driven.fused`:
      the same numbers to round-off, forward-mode derivatives in the same call) where it
      can (on the CPU, a bead's velocity or displacement, a C++ compiler at hand, and the
      chain's laws those it has: `DrivenChain.runs_on_fused_kernel`), else the JAX kernel;
      "jax" always the JAX kernel (reverse mode needs it). `LockinGrid.kernel` says which ran.

    **Returns:** `LockinGrid` with `.rms` and `.phase_rad` of shape (n_harmonics, F, A).
    """
    harmonics = tuple(float(h) for h in harmonics)
    if kernel not in ("auto", "jax"):
        raise ValueError(f'kernel: expected "auto" or "jax", got {kernel!r}.')
    check_grid_arguments(chain, frequencies_hz, drive_amplitudes_m, bead, quantity, harmonics, ramp_periods,
                         hold_periods, window_periods, steps_per_period, contact)
    contact = None if contact is None else int(contact)
    return _lockin_grid(chain.for_kernel(), jnp.asarray(frequencies_hz, dtype=jnp.float64),
                        jnp.asarray(drive_amplitudes_m, dtype=jnp.float64), int(bead), quantity, harmonics,
                        int(ramp_periods), int(hold_periods), int(window_periods), int(steps_per_period), int(unroll),
                        contact, kernel == "auto" and fused.runs(quantity) and chain.runs_on_fused_kernel)


@eqx.filter_jit
def _lockin_grid(chain, frequencies_hz, drive_amplitudes_m, bead, quantity, harmonics, ramp_periods,
                 hold_periods, window_periods, steps_per_period, unroll, contact, on_fused_kernel):
    n_freq, n_amp = frequencies_hz.shape[0], drive_amplitudes_m.shape[0]
    # one level per run, run index = i_f * A + i_a
    readings = lockin_runs(chain, jnp.repeat(frequencies_hz, n_amp), jnp.tile(drive_amplitudes_m, n_freq),
                           bead=bead, quantity=quantity, harmonics=harmonics, ramp_periods=ramp_periods,
                           hold_periods=hold_periods, window_periods=window_periods,
                           steps_per_period=steps_per_period, unroll=unroll, contact=contact,
                           on_fused_kernel=on_fused_kernel)
    return LockinGrid(
        complex_amplitude=readings.reshape(len(harmonics), n_freq, n_amp),
        frequencies_hz=frequencies_hz,
        drive_amplitudes_m=drive_amplitudes_m,
        harmonics=harmonics,
        quantity=quantity,
        bead=bead,
        contact=contact,
        kernel="fused" if on_fused_kernel else "jax",
    )


def lockin_runs(chain, frequency_hz, amplitude_m, *, bead, quantity, harmonics, ramp_periods, hold_periods,
                window_periods, steps_per_period, unroll, contact, on_fused_kernel) -> jax.Array:
    """The lock-in's complex amplitudes (n_harmonics, B) of B runs of `lockin_grid`, one per
    (`frequency_hz`, `amplitude_m`) pair ((B,) each), on the fused kernel (`on_fused_kernel`,
    where `fused.runs` says it can) or the JAX kernel (traceable; the chain `for_kernel`)."""
    if on_fused_kernel:
        return fused.lockin_sums(kernel_params(chain), frequency_hz, amplitude_m, steps_per_period=steps_per_period,
                                 ramp_periods=ramp_periods, hold_periods=hold_periods, window_periods=window_periods,
                                 harmonics=harmonics, bead=bead, quantity=quantity)
    schedule = HarmonicSchedule(frequency_hz[None], amplitude_m[None], steps_per_period, ramp_periods, hold_periods, 0)
    return lockin_levels(chain, schedule, bead, quantity, harmonics, window_periods, unroll,
                         contact).complex_amplitude[:, 0]


# The keywords of `lockin_grid` that say what a run is and what the lock-in reads (its
# read-out protocol); `run_lockin_sweep` takes the same, with the same defaults.
READOUT_KEYWORDS = ("bead", "quantity", "harmonics", "ramp_periods", "hold_periods", "window_periods",
                    "steps_per_period", "contact")


def readout_options(caller: str, **given) -> dict:
    """The read-out protocol of `lockin_grid` (`READOUT_KEYWORDS`): the `given` keywords, and
    `lockin_grid`'s defaults for the others. TypeError naming `caller` for a keyword that is
    not one of them."""
    unknown = sorted(set(given) - set(READOUT_KEYWORDS))
    if unknown:
        raise TypeError(f"{caller}: unknown keyword(s) {', '.join(unknown)}; the read-out keywords are "
                        f"{', '.join(READOUT_KEYWORDS)} (as for lockin_grid).")
    parameters = inspect.signature(lockin_grid).parameters
    return {name: given.get(name, parameters[name].default) for name in READOUT_KEYWORDS}


def settle_periods(chain: DrivenChain, frequency_hz: float, tolerance: float = 1e-4) -> int:
    """Periods of `frequency_hz` after which a transient of the least damped bead has decayed
    to `tolerance` of its start, $\\lceil 2\\ln(1/\\mathrm{tol})\\,f/\\gamma_{\\min}\\rceil$ (the
    envelope of a viscously damped oscillation falls as $e^{-\\gamma t/2}$). Concrete inputs."""
    rate = float(np.min(np.asarray(chain.damping_rate_per_s)))
    if rate <= 0.0:
        raise ValueError("settle_periods: a chain without damping (damping_rate_per_s = 0) never settles.")
    return int(np.ceil(2.0 * np.log(1.0 / tolerance) * float(frequency_hz) / rate))


def check_grid_arguments(chain, frequencies_hz, drive_amplitudes_m, bead, quantity, harmonics, ramp_periods,
                         hold_periods, window_periods, steps_per_period, contact=None) -> None:
    """ValueError naming the argument for a grid `lockin_grid` cannot run (concrete values)."""
    for name, value in (("ramp_periods", ramp_periods), ("hold_periods", hold_periods)):
        if int(value) != value or value < 0:
            raise ValueError(f"{name}: expected a whole number of periods >= 0, got {value}.")
    for name, values, unit in (("frequencies_hz", frequencies_hz, "Hz"), ("drive_amplitudes_m", drive_amplitudes_m, "m")):
        if isinstance(values, jax.core.Tracer):
            continue
        array = np.asarray(values, dtype=float)
        if array.ndim != 1 or array.size == 0:
            raise ValueError(f"{name}: expected a non-empty 1-D array ({unit}), got shape {array.shape}.")
        if not np.all(np.isfinite(array)) or (name == "frequencies_hz" and np.any(array <= 0)) or np.any(array < 0):
            raise ValueError(f"{name}: values must be finite and {'> 0' if name == 'frequencies_hz' else '>= 0'} "
                             f"({unit}), got {array}.")
    check_readout(chain, bead, quantity, harmonics, window_periods, hold_periods, steps_per_period, frequencies_hz,
                  contact)
