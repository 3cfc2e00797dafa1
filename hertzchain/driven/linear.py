"""The linearised chain at a static precompression: normal modes, frequency response, bands.

Under a static force $F_0$ every Hertz contact sits at the overlap $\\delta_0 = (F_0/\\kappa)^{2/3}$
and, for small motion about it, acts as a spring of stiffness
$k = dF/d\\delta|_{\\delta_0} = \\tfrac32\\kappa^{2/3}F_0^{1/3}$
(`DrivenChain.contact_stiffness_n_m`). A chain of n beads between a driven
face (contact 0) and a wall (contact n) then has the stiffness matrix K (n, n), tridiagonal,
the mass matrix M = diag(m) and the viscous matrix C = diag(m gamma) (a force $-m\\gamma v$ on
each bead). Micro-slip supports (`laws.IwanSupport`) add their stiffness before anything slips
to each bead's diagonal entry (`DrivenChain.support_stiffness_n_m`: under an infinitesimal
motion every slider sticks); the linear model then holds below the supports' slip, and:

- `normal_modes`: $K v = \\omega^2 M v$ (face and wall held), frequencies in Hz and mass-normalised
  shapes;
- `frequency_response`: the complex amplitudes of every bead's displacement for a face moving
  as $u\\,e^{i\\omega t}$, per metre of $u$: $X = (K - \\omega^2 M + i\\omega C)^{-1} k_0 e_1$, and
  the dynamic forces of every contact;
- `band_structure`: the Bloch frequencies $\\omega(q)$ of the periodic chain built from a unit cell
  of masses and contact stiffnesses; a monatomic chain's band edge is
  $f = \\frac1\\pi\\sqrt{k/m}$ (`monatomic_band_edge_hz`).

The chain is a `DrivenChain` (the constants the nonlinear `lockin_grid` runs on). Everything
is `jax.numpy`, float64, differentiable in every physical argument.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .chain import DrivenChain


def stiffness_matrix(contact_stiffness_n_m, support_stiffness_n_m=0.0):
    """K (n, n), N/m, of n beads joined by n + 1 springs (`contact_stiffness_n_m` (n+1,):
    0 = driven face-bead 1, K = bead K-K+1, n = bead n-wall), face and wall held, each bead
    also held to ground by `support_stiffness_n_m` (scalar or (n,), N/m; default none)."""
    k = jnp.asarray(contact_stiffness_n_m, dtype=float)
    diagonal = k[:-1] + k[1:] + jnp.asarray(support_stiffness_n_m, dtype=float)
    off = -k[1:-1]
    return jnp.diag(diagonal) + jnp.diag(off, 1) + jnp.diag(off, -1)


def normal_modes(chain: DrivenChain):
    """Normal modes of the linearised `chain`, face and wall held (the supports' stiffness
    included).

    **Returns:** `(frequencies_hz (n,), shapes (n, n))`, ascending; column j of `shapes` is
    mode j, normalised so that shapes.T M shapes = 1 (m in units of sqrt(kg)^-1).
    """
    stiffness = stiffness_matrix(chain.contact_stiffness_n_m(), chain.support_stiffness_n_m())
    scale = 1.0 / jnp.sqrt(chain.bead_mass_kg)
    omega2, vectors = jnp.linalg.eigh(scale[:, None] * stiffness * scale[None, :])
    return jnp.sqrt(jnp.maximum(omega2, 0.0)) / (2 * jnp.pi), scale[:, None] * vectors


def frequency_response(chain: DrivenChain, frequencies_hz):
    """Steady response of the linearised `chain` to the face moving as $u\\,e^{i\\omega t}$ at
    `frequencies_hz` (F,), with the supports' stiffness and the chain's viscous damping ($-m\\gamma v$ on each bead; its
    Kuwabara-Kono `eta_s` is not part of the linear model).

    **Returns:** `(displacement, contact_force)`: complex (F, n) bead displacements per metre
    of face amplitude (m/m; the velocity is $i\\omega$ times it) and complex (F, n+1) dynamic
    forces of the contacts per metre of face amplitude (N/m), compression positive.
    """
    mass = chain.bead_mass_kg
    k = chain.contact_stiffness_n_m()
    stiffness = stiffness_matrix(k, chain.support_stiffness_n_m())
    damping = chain.damping_rate_per_s * mass
    omega = 2 * jnp.pi * jnp.asarray(frequencies_hz, dtype=float)
    load = jnp.zeros(mass.shape, complex).at[0].set(k[0])

    def one(w):
        dynamic = stiffness - w**2 * jnp.diag(mass) + 1j * w * jnp.diag(damping)
        x = jnp.linalg.solve(dynamic, load)
        ends = jnp.concatenate([jnp.ones(1, complex), x, jnp.zeros(1, complex)])
        return x, k * (ends[:-1] - ends[1:])

    return jax.vmap(one)(omega)


def band_structure(cell_mass_kg, cell_kappa_n_m1p5, precompression_n, wavenumbers):
    """Bloch frequencies (Hz) of the infinite periodic chain under the static force
    `precompression_n` (N).

    The unit cell holds p beads (`cell_mass_kg` (p,)) and p Hertz contacts
    (`cell_kappa_n_m1p5` (p,), N/m^{3/2}): contact j joins bead j to bead j+1, the last one
    bead p-1 to bead 0 of the next cell. `wavenumbers` (Q,) are q times the cell length
    (radians per cell, -pi..pi).

    **Returns:** (Q, p) frequencies in Hz, ascending in each row.
    """
    mass = jnp.atleast_1d(jnp.asarray(cell_mass_kg, dtype=float))
    kappa = jnp.atleast_1d(jnp.asarray(cell_kappa_n_m1p5, dtype=float))
    # the cell's contacts as a chain's (its last contact repeated as the closing one)
    k = DrivenChain(mass, jnp.concatenate([kappa, kappa[-1:]]), precompression_n, 0.0).contact_stiffness_n_m()[:-1]
    p = mass.shape[0]
    index = jnp.arange(p)
    following = (index + 1) % p
    scale = 1.0 / jnp.sqrt(mass)

    def one(q):
        phase = jnp.where(index == p - 1, jnp.exp(1j * q), 1.0 + 0j)  # the last contact reaches the next cell
        matrix = jnp.zeros((p, p), complex)
        matrix = matrix.at[index, index].add(k)
        matrix = matrix.at[following, following].add(k)
        matrix = matrix.at[index, following].add(-k * phase)
        matrix = matrix.at[following, index].add(-k * jnp.conj(phase))
        omega2 = jnp.linalg.eigvalsh(scale[:, None] * matrix * scale[None, :])
        return jnp.sqrt(jnp.maximum(omega2, 0.0)) / (2 * jnp.pi)

    return jax.vmap(one)(jnp.asarray(wavenumbers, dtype=float))


def monatomic_band_edge_hz(bead_mass_kg, contact_kappa_n_m1p5, precompression_n):
    """Top of the acoustic band of a chain of equal beads (kg) and contacts (N/m^{3/2}) under
    `precompression_n` (N; scalar or array): $\\frac1\\pi\\sqrt{k/m}$, Hz."""
    def edge(force_n):
        return band_structure(bead_mass_kg, contact_kappa_n_m1p5, force_n, jnp.array([jnp.pi]))[0, 0]

    return jnp.vectorize(edge)(jnp.asarray(precompression_n, dtype=float))


def symmetric_pair_stiffness_n_m(mode_frequencies_hz, bead_mass_kg, support_stiffness_n_m=0.0):
    """The contact stiffnesses of two equal beads between two equal end contacts from their two
    linear mode frequencies: the inverse of `normal_modes` for n = 2. With end contacts $k_e$,
    the bead-bead one $k_m$ and each bead's supports $k_s$ (N/m), the modes are
    $m\\omega_1^2 = k_e + k_s$ (in phase) and $m\\omega_2^2 = k_e + 2k_m + k_s$ (in antiphase).

    **Arguments:** `mode_frequencies_hz` (2,), ascending, Hz; `bead_mass_kg`, kg;
    `support_stiffness_n_m`, N/m (default 0).

    **Returns:** `(end_n_m, middle_n_m)`, N/m.
    """
    f = jnp.asarray(mode_frequencies_hz, dtype=float)
    if f.shape != (2,):
        raise ValueError(f"mode_frequencies_hz: expected the two mode frequencies (Hz), got shape {f.shape}.")
    stiffness = bead_mass_kg * (2 * jnp.pi * f) ** 2
    return stiffness[0] - support_stiffness_n_m, 0.5 * (stiffness[1] - stiffness[0])
