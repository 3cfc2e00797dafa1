"""Shared pieces of the tests: independent references written in NumPy from their papers, which
several test files compare the library with (a test file imports them from here, never from
another test file)."""

import math

import numpy as np


def jackson_green_force(overlap, peak, kappa, radius, sigma, nu, hardness=2.84):
    """Jackson & Green (2005) loading with hardness h sigma_Y, Hertz unloading about the residual:
    the contact force (N) at `overlap` (m) after the largest overlap `peak` (m), for a Hertz
    constant `kappa` (N/m^1.5), reduced radius `radius` (m), yield stress `sigma` (Pa) and
    Poisson ratio `nu`. Written from the paper, independently of `hertzchain.contact`."""
    modulus = 3 * kappa / (4 * np.sqrt(radius))
    c = 1.295 * math.exp(0.736 * nu)
    critical = (math.pi * c * sigma / (2 * modulus)) ** 2 * radius
    exponent = 0.14 * np.exp(23 * sigma / modulus)

    def load(x):
        return np.exp(-0.25 * x ** (5 / 12)) * x**1.5 + 4 * hardness / c * (1 - np.exp(-x ** (5 / 9) / 25)) * x

    ratio = peak / critical
    yielded = ratio > 1.9
    r = np.where(yielded, ratio, 1.9)
    peak_force = np.where(yielded, kappa * critical**1.5 * (load(r) - load(1.9) + 1.9**1.5), kappa * peak**1.5)
    contact_radius = np.sqrt(radius * peak * np.where(yielded, (r / 1.9) ** exponent, 1.0))
    span = np.where(yielded, 3 * peak_force / (4 * modulus * np.maximum(contact_radius, 1e-300)), peak)
    fraction = np.clip((overlap - (peak - span)) / np.maximum(span, 1e-300), 0.0, None)
    return np.where(peak > 0, peak_force * fraction**1.5, 0.0)
