"""Natural terrain of the realistic worlds: a seeded fractal surface by spectral synthesis.

Real topography is close to a self-affine surface whose 2-D power spectrum falls as k^-beta,
beta = 2 H + 2 with a Hurst exponent H of about 0.8-0.9 (fractal dimension about 2.1-2.2,
Huang & Turcotte 1989, "Fractal mapping of digitized images: application to the topography of
Arizona and comparisons with synthetic images", J. Geophys. Res. 94(B6)); beta = 3.8 here.
The surface is synthesised on a local east/north grid by filtering white noise in the Fourier
domain; a roll-off at ``longest_m`` keeps its variance finite. Land cover (forest and town
patches, for the DEM's canopy and building offsets) is a thresholded smooth noise field.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import map_coordinates

SPECTRAL_EXPONENT = 3.8
FADE_M = 2000.0
"""Beyond the synthesised patch the surface fades into its base level over about this distance."""


@dataclass
class GridField:
    """Values on a regular local grid (row = north index, column = east index)."""

    east0_m: float
    north0_m: float
    step_m: float
    values: np.ndarray
    outside: float = 0.0

    def at(self, east_m, north_m) -> np.ndarray:
        """Bilinear value at local positions [m]; fades to ``outside`` beyond the grid."""
        east, north = np.asarray(east_m, float), np.asarray(north_m, float)
        col = (east - self.east0_m) / self.step_m
        row = (north - self.north0_m) / self.step_m
        rows, cols = self.values.shape
        inside = map_coordinates(self.values, [np.clip(row, 0, rows - 1).ravel(), np.clip(col, 0, cols - 1).ravel()],
                                 order=1, mode="nearest").reshape(east.shape)
        beyond = np.hypot(np.maximum(np.maximum(-row, row - rows + 1), 0.0),
                          np.maximum(np.maximum(-col, col - cols + 1), 0.0)) * self.step_m
        fade = np.exp(-(beyond / FADE_M) ** 2)
        return fade * inside + (1.0 - fade) * self.outside

    @property
    def bounds_m(self) -> tuple[float, float, float, float]:
        rows, cols = self.values.shape
        return (self.east0_m, self.east0_m + (cols - 1) * self.step_m,
                self.north0_m, self.north0_m + (rows - 1) * self.step_m)


def spectral_surface(rng: np.random.Generator, shape: tuple[int, int], step_m: float, longest_m: float,
                     beta: float = SPECTRAL_EXPONENT) -> np.ndarray:
    """Zero-mean, unit-RMS surface with power spectrum (k^2 + k0^2)^(-beta/2), k0 = 1/longest_m."""
    white = rng.standard_normal(shape)
    ky = np.fft.fftfreq(shape[0], step_m)[:, None]
    kx = np.fft.rfftfreq(shape[1], step_m)[None, :]
    amplitude = (kx * kx + ky * ky + (1.0 / longest_m) ** 2) ** (-beta / 4.0)
    surface = np.fft.irfft2(np.fft.rfft2(white) * amplitude, s=shape)
    surface -= surface.mean()
    return surface / surface.std()


def natural_terrain(rng: np.random.Generator, bounds_m: tuple[float, float, float, float], relief_m: float,
                    base_m: float, step_m: float = 25.0, pad_m: float = 4000.0,
                    longest_m: float = 15_000.0) -> GridField:
    """Fractal terrain [m] over the east/north ``bounds_m`` plus ``pad_m``, RMS ``relief_m``
    around ``base_m``."""
    e0, e1, n0, n1 = bounds_m[0] - pad_m, bounds_m[1] + pad_m, bounds_m[2] - pad_m, bounds_m[3] + pad_m
    shape = (int(np.ceil((n1 - n0) / step_m)) + 1, int(np.ceil((e1 - e0) / step_m)) + 1)
    heights = base_m + relief_m * spectral_surface(rng, shape, step_m, longest_m)
    return GridField(e0, n0, step_m, heights, outside=base_m)


def cover_fraction_field(rng: np.random.Generator, like: GridField, fraction: float,
                         patch_m: float = 1500.0) -> GridField:
    """1 on patches covering about ``fraction`` of the area (patches of about ``patch_m``), else 0;
    edges soft over one coarse cell."""
    step = max(like.step_m, patch_m / 10.0)
    e0, e1, n0, n1 = like.bounds_m
    shape = (int(np.ceil((n1 - n0) / step)) + 1, int(np.ceil((e1 - e0) / step)) + 1)
    if fraction <= 0.0:
        return GridField(e0, n0, step, np.zeros(shape), 0.0)
    field = spectral_surface(rng, shape, step, patch_m, beta=4.0)
    threshold = np.quantile(field, 1.0 - min(fraction, 1.0))
    return GridField(e0, n0, step, (field >= threshold).astype(float), 0.0)
