"""Road gradient (paper §2.2.1, equations (5)-(8)): map-matching on a DEM, barometric height,
IMU, and their accuracy-weighted fusion on a distance grid.

Public: `estimate_gradient(frame, dem, settings) -> GradientResult`, `GradientSettings`; the
pipeline's stage, which adds ``height_m``, ``gradient_pct`` and each source's columns, is
`analysis.gradient.stage.gradient_stage`.
"""

from __future__ import annotations

from .estimate import GradientResult, GradientSettings, estimate_gradient

__all__ = ["estimate_gradient", "GradientResult", "GradientSettings"]
