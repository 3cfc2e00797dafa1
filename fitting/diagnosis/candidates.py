"""Where each candidate effect is refitted from, and what its fitted strengths mean in
lab units."""

from __future__ import annotations

import math

import numpy as np

from hertzchain import laws

from .. import effects as fx
from .protocol import (
    _VARIANT,
    PRELOAD_START_FRACTIONS,
    REFIT_STARTS,
    SENSOR_START_F0_HZ,
    YIELD_START_FRACTIONS,
)


class _Candidates:
    """The candidates' starts and interpretation for `_Search`."""

    def start_for(self, effect: str, x) -> list[np.ndarray]:
        """Start vectors for refitting `effect` from the current fit `x`.

        Where a candidate's objective is flat or singular, and how its starts get past it:

        - `plasticity`: flat (exactly the base model) while the yield force is above every
          force the chain reaches; a refit from there never moves. Starts: yield forces from
          the largest observed force downwards (1.0 ... 0.35 of it).
        - `precompression`: the static overlap grows as F0^(2/3), infinitely steep at 0, so
          a linear score at 0 says little. Starts: F0 on a geometric grid (0.3 % to 30 % of
          the smallest observed peak; steps of 3 in F0, 1.44 in F0^(1/3), where the effect is
          smooth), each read by AC (piezo) and by DC channels (`preload_seen` 0 and 1).
        - `track_friction`: beads stick below mu g; the effect on a pulse is a threshold in
          amplitude. Starts: mu = 0.01, 0.05, 0.2.
        - `viscous_damping`: smooth from 0; starts 0.3, 1 and 3 us cover its range.
        - `dashpot_damping`: smooth from 0; starts at 0.3, 1 and 3 % of the critical
          damping of a contact linearised at the largest observed force.
        - `sensor_dynamics`: multimodal in f0 (the ringing's phase): a grid of f0 and beta,
          each with the split-bead mechanics (coupling 1) and the paper's filter form (0).
        - `wall_compliance`: smooth; starts at the header's wall and a wall e^2 softer.
        - `contact_exponent`: its derivative at n = 3/2 is taken on Hertz contacts, where the
          exponent does not enter (0): it is scored by secants to n = 1.4 ... 1.7 instead.
        """
        x = x.copy()
        cols = self.effect_columns[effect]

        def start(*values):
            s = x.copy()
            s[cols[:len(values)]] = values
            return s

        largest = max(float(np.max(e.data(c))) for e in self.problem.experiments for c in e.channels)
        smallest = min(max(float(np.max(e.data(c))) for c in e.channels) for e in self.problem.experiments)
        if effect == "viscous_damping":
            return [start(value) for value in (0.3e-6, 1e-6, 3e-6)]
        if effect == "dashpot_damping":
            # a few thousandths to a few hundredths of the critical damping of a contact
            # linearised at the largest observed force
            setup = self.problem.base_setups[0]
            kappa, mass = setup.contact_kappa()[1], float(setup.bead_mass_kg[0])
            stiffness = float(setup.contact_law.stiffness_at_force(largest, laws.ContactConstants(kappa)))
            critical = 2.0 * math.sqrt(stiffness * mass)
            return [start(share * critical) for share in (0.003, 0.01, 0.03)]
        if effect == "track_friction":
            return [start(value) for value in (0.01, 0.05, 0.2)]
        if effect == "sensor_dynamics":
            return [start(beta, (fx.SENSOR_REFERENCE_HZ / f0_hz) ** 2, coupling)
                    for coupling in (1.0, 0.0) for beta in (0.05, 0.15) for f0_hz in SENSOR_START_F0_HZ]
        if effect == "precompression":
            return [start(fraction * smallest, seen) for seen in (0.0, 1.0)
                    for fraction in PRELOAD_START_FRACTIONS]
        if effect == "plasticity":
            nominal = float(np.min(self._nominal_yield_forces()))
            return [start((nominal / (fraction * largest)) ** (1 / 3)) for fraction in YIELD_START_FRACTIONS]
        if effect == "wall_compliance":
            return [start(value) for value in (0.0, 2.0)]
        if effect == "contact_exponent":
            return [start(shift) for shift in (-0.1, -0.04, 0.04, 0.1, 0.2)]
        return [x]

    def interpret(self, effect: str, x, effects=(), chi2: float = 0.0) -> str:
        """A sentence on which law or reading of a named effect the fitted strengths say
        (empty for effects with one law); `effects` and `chi2`: the fit's, for standard errors."""
        value = {self.labels[c]: float(x[c]) for c in self.effect_columns[effect]}
        if effect == "sensor_dynamics":
            c = value["sensor_coupling"]
            form = ("the split-bead mechanics (the sensor's compression shortens its bead)" if c > 0.5 else
                    "the paper's filter form of Eq. 4 (the chain unaffected by the sensor)")
            f0 = fx.SENSOR_REFERENCE_HZ / math.sqrt(value["sensor_rate"]) if value["sensor_rate"] > 0 else math.inf
            return (f" sensor_dynamics: the data prefer {form}, coupling {c:.3g} (0: filter, 1: split bead); "
                    f"beta {value['sensor_beta']:.3g}, f0 {f0 / 1e3:.4g} kHz.")
        if effect == "precompression":
            seen = value["preload_seen"]
            reading = ("read as changes of force (AC-coupled, piezo sensors)" if seen < 0.5 else
                       "read with its static part (DC-coupled sensors)")
            return f" precompression: static preload {value['preload_n']:.4g} N, {reading}; share seen {seen:.3g}."
        if effect == "contact_exponent":
            return f" contact_exponent: contacts follow F ~ delta^n with n = {1.5 + value['exponent_shift']:.4g}."
        if effect in ("plasticity", "wall_compliance"):
            cols = self.columns(effects)
            column = self.effect_columns[effect][0]
            error = float(self.stderr(x, cols, chi2)[cols.index(column)]) if column in cols else math.nan
            if effect == "wall_compliance":
                return fx.describe_wall(self.problem.base_setups[0], value["wall_softening"], error)
            if value["yield_softening"] > 0:
                return fx.describe_plasticity(self.problem.base_setups[0], value["yield_softening"], error)
        return ""

    def _nominal_yield_forces(self) -> np.ndarray:
        """Every contact's yield force (N) at yield_softening 1 (`fitting.effects.nominal_yield_forces_n`)."""
        return fx.nominal_yield_forces_n(self.problem.base_setups[0])

    def _chosen_starts(self, name, ranked) -> list:
        """The best of `ranked` starts: the best of each variant of the law, then the next
        best up to `REFIT_STARTS`."""
        chosen = []
        if name in _VARIANT:
            column, variants = self.effect_columns[name][_VARIANT[name]], set()
            for s in ranked:
                if float(s[column]) not in variants:
                    variants.add(float(s[column]))
                    chosen.append(s)
        for s in ranked:
            if len(chosen) >= REFIT_STARTS.get(name, 1):
                break
            if all(s is not c for c in chosen):
                chosen.append(s)
        return chosen
