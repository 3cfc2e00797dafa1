"""The linearised chain at a static precompression: normal modes, frequency response, bands.

Under a static force $F_0$ every Hertz contact sits at the overlap $\\delta_0 = (F_0/\\kappa)^{2/3}$
and, for small motion about it, acts as a spring of stiffness
$k = dF/d\\delta|_{\\delta_0} = \\tfrac32\\kappa^{2/3}F_0^{1/3}$ (`contact_stiffness_n_m`, the
derivative of `hertzchain.contact.hertz_force` itself). A chain of n beads between a driven
face (contact 0) and a wall (contact n) then has the stiffness matrix K (n, n), tridiagonal,
the mass matrix M = diag(m) and the viscous matrix C = diag(m gamma) (a force $-m\\gamma v$ on
each bead), and:

- `normal_modes`: $K v = \\omega^2 M v$ (face and wall held), frequencies in Hz and mass-normalised
  shapes;
- `frequency_response`: the complex amplitudes of every bead's displacement for a face moving
  as $u\\,e^{i\\omega t}$, per metre of $u$: $X = (K - \\omega^2 M + i\\omega C)^{-1} k_0 e_1$, and
  the dynamic forces of every contact;
- `band_structure`: the Bloch frequencies $\\omega(q)$ of the periodic chain built from a unit cell
  of masses and contact stiffnesses; a monatomic chain's band edge is
  $f = \\frac1\\pi\\sqrt{k/m}$ (`monatomic_band_edge_hz`).

Everything is `jax.numpy`, float64, differentiable in every physical argument.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ..contact import hertz_force, overlap_at_force


def contact_stiffness_n_m(contact_kappa_n_m1p5, precompression_n):
    """Tangent stiffness $dF/d\\delta$ (N/m) of Hertz contacts ($\\kappa$, N/m^{3/2}) carrying the
    static force `precompression_n` (N): $\\tfrac32\\kappa^{2/3}F_0^{1/3}$."""
    kappa = jnp.asarray(contact_kappa_n_m1p5, dtype=float)
    overlap = overlap_at_force(jnp.asarray(precompression_n, dtype=float), kappa)
    slope = jax.grad(hertz_force)
    return jnp.vectorize(slope)(overlap * jnp.ones_like(kappa), kappa)


def stiffness_matrix(contact_stiffness_n_m):
    """K (n, n), N/m, of n beads joined by n + 1 springs (`contact_stiffness_n_m` (n+1,):
    0 = driven face-bead 1, K = bead K-K+1, n = bead n-wall), face and wall held."""
    k = jnp.asarray(contact_stiffness_n_m, dtype=float)
    diagonal = k[:-1] + k[1:]
    off = -k[1:-1]
    return jnp.diag(diagonal) + jnp.diag(off, 1) + jnp.diag(off, -1)


def normal_modes(bead_mass_kg, contact_kappa_n_m1p5, precompression_n):
    """Normal modes of the linearised chain, face and wall held.

    **Returns:** `(frequencies_hz (n,), shapes (n, n))`, ascending; column j of `shapes` is
    mode j, normalised so that shapes.T M shapes = 1 (m in units of sqrt(kg)^-1).
    """
    mass = jnp.asarray(bead_mass_kg, dtype=float)
    stiffness = stiffness_matrix(contact_stiffness_n_m(contact_kappa_n_m1p5, precompression_n))
    scale = 1.0 / jnp.sqrt(mass)
    omega2, vectors = jnp.linalg.eigh(scale[:, None] * stiffness * scale[None, :])
    return jnp.sqrt(jnp.maximum(omega2, 0.0)) / (2 * jnp.pi), scale[:, None] * vectors


def frequency_response(bead_mass_kg, contact_kappa_n_m1p5, precompression_n, damping_rate_per_s, frequencies_hz):
    """Steady response of the linearised chain to the face moving as $u\\,e^{i\\omega t}$.

    **Arguments:** `bead_mass_kg` (n,), `contact_kappa_n_m1p5` (n+1,), `precompression_n` (N),
    `damping_rate_per_s` (n,) or a number (gamma of the viscous force $-m\\gamma v$),
    `frequencies_hz` (F,).

    **Returns:** `(displacement, contact_force)`: complex (F, n) bead displacements per metre
    of face amplitude (m/m; the velocity is $i\\omega$ times it) and complex (F, n+1) dynamic
    forces of the contacts per metre of face amplitude (N/m), compression positive.
    """
    mass = jnp.asarray(bead_mass_kg, dtype=float)
    k = contact_stiffness_n_m(contact_kappa_n_m1p5, precompression_n)
    stiffness = stiffness_matrix(k)
    damping = jnp.broadcast_to(jnp.asarray(damping_rate_per_s, dtype=float), mass.shape) * mass
    omega = 2 * jnp.pi * jnp.asarray(frequencies_hz, dtype=float)
    load = jnp.zeros(mass.shape, complex).at[0].set(k[0])

    def one(w):
        dynamic = stiffness - w**2 * jnp.diag(mass) + 1j * w * jnp.diag(damping)
        x = jnp.linalg.solve(dynamic, load)
        ends = jnp.concatenate([jnp.ones(1, complex), x, jnp.zeros(1, complex)])
        return x, k * (ends[:-1] - ends[1:])

    return jax.vmap(one)(omega)


def band_structure(cell_mass_kg, cell_kappa_n_m1p5, precompression_n, wavenumbers):
    """Bloch frequencies (Hz) of the infinite periodic chain.

    The unit cell holds p beads (`cell_mass_kg` (p,)) and p contacts (`cell_kappa_n_m1p5`
    (p,)): contact j joins bead j to bead j+1, the last one bead p-1 to bead 0 of the next
    cell. `wavenumbers` (Q,) are q times the cell length (radians per cell, -pi..pi).

    **Returns:** (Q, p) frequencies in Hz, ascending in each row.
    """
    mass = jnp.asarray(cell_mass_kg, dtype=float)
    k = contact_stiffness_n_m(cell_kappa_n_m1p5, precompression_n)
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
    """Top of the acoustic band of a chain of equal beads: $\\frac1\\pi\\sqrt{k/m}$, Hz."""
    k = contact_stiffness_n_m(contact_kappa_n_m1p5, precompression_n)
    return jnp.sqrt(k / jnp.asarray(bead_mass_kg, dtype=float)) / jnp.pi
