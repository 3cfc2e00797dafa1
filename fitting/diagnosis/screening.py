"""Screening: every candidate's score, the chi^2 a Gauss-Newton step (or its secants) on its
strengths alone would remove, projected off the free parameters."""

from __future__ import annotations

import numpy as np


class _Screening:
    """The screen of `_Search`."""

    # --- screening --------------------------------------------------------------------------------
    def screen(self, x, effects_in, names) -> tuple[dict, dict, dict, list]:
        """Scores, best starts, separability and pairwise distinguishability at the fit `x`.

        The score of a candidate is the chi^2 a Gauss-Newton step on its strengths (with
        every free parameter re-adjusted, i.e. projected off their sensitivities) would
        remove: from its Jacobian columns at `x` (exact derivatives at "off") and from the
        secant to each start value (one residual evaluation each: this is what scores
        effects with a threshold, such as plasticity, whose derivative at "off" is 0).
        """
        r, jac = self.evaluate(x)
        active = self.columns(effects_in)
        q, _ = np.linalg.qr(jac[:, active])

        def project(block):
            return block - q @ (q.T @ block)

        def gain(block):
            u, sv, _ = np.linalg.svd(project(block), full_matrices=False)
            keep = sv > 1e-8 * (sv[0] if sv.size else 1.0)
            return float(np.sum((u[:, keep].T @ r) ** 2)) if keep.any() else 0.0, (u[:, 0] if keep.any() else None)

        scores, starts, separable, vectors = {}, {}, {}, {}
        for name in names:
            cols = self.effect_columns[name]
            block = jac[:, cols]
            # strengths whose derivative at x the evaluated law does not carry (the contact
            # exponent at n = 3/2, on Hertz contacts: its column is 0): each secant stands for
            # their column and is scored together with the candidate's derived columns (the
            # stiffness at the reference overlap), as a Gauss-Newton step on all its strengths
            # would be. Scored apart, contact_exponent's score was its stiffness column's
            # alone, equal to rotational_friction's (the same uniform scale), and the order of
            # the library broke the tie: on the paper chain's independent data with n = 1.6
            # hidden it was not refitted in the first round (both 1.66e5), and bead_dispersion
            # (21 radii) was named first, to be dropped by the backward check.
            raw = np.linalg.norm(block, axis=0)
            off = self.evaluate.off_variant(x, cols)
            derived = [i for i, c in enumerate(cols) if c not in off or raw[i] > 0]
            kept = np.linalg.norm(project(block), axis=0)
            if np.any(raw > 0):
                separable[name] = bool(np.max(kept / np.where(raw > 0, raw, 1.0)) > 1e-4)
            else:
                separable[name] = True
            best, vector = gain(block) if np.any(raw > 0) else (0.0, None)
            secants = []  # (gain, start): the refit starts from the best secants' end points
            for start in self.start_for(name, x):
                delta = start[cols] - x[cols]
                if not np.any(delta != 0):
                    continue
                secant = (self.evaluate.residuals(start) - r)[:, None]
                # separable also when a secant keeps its part off the free parameters: the
                # derivative at "off" can miss the effect (contact_exponent's, on Hertz contacts,
                # is only its stiffness prefactor, a uniform scale that per-bead radii span)
                norm = float(np.linalg.norm(secant))
                if norm > 0 and float(np.linalg.norm(project(secant))) > 1e-4 * norm:
                    separable[name] = True
                g, v = gain(np.column_stack([block[:, derived], secant]) if len(derived) < len(cols) else secant)
                secants.append((g, start))
                if g > best:
                    best = g
                    vector = v if vector is None else vector
            secants.sort(key=lambda pair: -pair[0])
            scores[name] = best
            starts[name] = self._chosen_starts(name, [start for _, start in secants]) or [x]
            if vector is not None:
                vectors[name] = vector
        pairs = []
        listed = list(vectors)
        for i in range(len(listed)):
            for j in range(i + 1, len(listed)):
                c = abs(float(vectors[listed[i]] @ vectors[listed[j]]))
                if c > 0.95:
                    pairs.append({"effects": [listed[i], listed[j]], "abs_cos": c})
        return scores, starts, separable, pairs
