"""Road gradient (paper §2.2.1, equations (5)-(8)): map-matching on a DEM, barometric height,
IMU, the paper's accuracy-weighted fusion (8), and a Kalman smoother over distance that fuses all
of them with data-estimated noise levels (the default ``gradient_pct``).

Public: `estimate_gradient(frame, dem, settings) -> GradientResult`, `GradientSettings`; the
pipeline's stage, which adds ``height_m``, ``gradient_pct`` and each source's columns, is
`analysis.gradient.stage.gradient_stage`.
"""

from __future__ import annotations

from .estimate import GradientResult, GradientSettings, estimate_gradient

__all__ = ["estimate_gradient", "GradientResult", "GradientSettings"]
