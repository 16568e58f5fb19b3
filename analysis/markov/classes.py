"""Class grid of the Markov chain: speed, gradient and mass classes and their int64 state key.

A class index is the value divided by the class width, rounded to the nearest integer, so class
``k`` is centred on ``k · width``: speed class 0 is standstill (|v| < width/2), gradient class 0 is
level road. The state key packs (speed class, gradient class, mass class) into one int64 whose low
43 bits are the combined gradient-and-mass class of physics.md; the encoding does not depend on
the data, so counts from different logs share keys and add up.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import UserError

KMH_PER_MPS = 3.6
SPEED_BITS, GRADIENT_BITS, MASS_BITS = 20, 21, 22
GRADIENT_OFFSET = 1 << (GRADIENT_BITS - 1)
MASS_SHIFT = 0
GRADIENT_SHIFT = MASS_BITS
SPEED_SHIFT = MASS_BITS + GRADIENT_BITS


class ClassError(UserError):
    pass


@dataclass(frozen=True)
class ClassWidths:
    """Class widths of the chain: speed [km/h], gradient [%], mass [kg]."""

    speed_kmh: float = 1.0
    gradient_pct: float = 0.5
    mass_kg: float = 100.0

    def __post_init__(self):
        for name in ("speed_kmh", "gradient_pct", "mass_kg"):
            value = getattr(self, name)
            if not np.isfinite(value) or value <= 0:
                raise ClassError(f"class width {name} must be a positive number, got {value}")

    @property
    def speed_mps(self) -> float:
        """Speed class width [m/s]."""
        return self.speed_kmh / KMH_PER_MPS

    def as_dict(self) -> dict:
        return {"speed_kmh": self.speed_kmh, "gradient_pct": self.gradient_pct, "mass_kg": self.mass_kg}


def class_index(values: np.ndarray, width: float) -> np.ndarray:
    """Nearest class index of ``values`` for classes centred on multiples of ``width``."""
    return np.floor(np.asarray(values, dtype=float) / width + 0.5).astype(np.int64)


def encode(speed_class: np.ndarray, gradient_class: np.ndarray, mass_class: np.ndarray) -> np.ndarray:
    """Pack class indices into int64 state keys (see the module docstring)."""
    speed_class = np.asarray(speed_class, dtype=np.int64)
    gradient_shifted = np.asarray(gradient_class, dtype=np.int64) + GRADIENT_OFFSET
    mass_class = np.asarray(mass_class, dtype=np.int64)
    for name, values, bits in (("speed", speed_class, SPEED_BITS), ("gradient", gradient_shifted, GRADIENT_BITS),
                               ("mass", mass_class, MASS_BITS)):
        if values.size and (values.min() < 0 or values.max() >= (1 << bits)):
            raise ClassError(f"{name} classes out of range for the state key: check units "
                             f"(speed in m/s, gradient in %, mass in kg) and class widths")
    return (speed_class << SPEED_SHIFT) | (gradient_shifted << GRADIENT_SHIFT) | (mass_class << MASS_SHIFT)


def decode(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Class indices (speed, gradient, mass) of int64 state keys."""
    keys = np.asarray(keys, dtype=np.int64)
    speed = keys >> SPEED_SHIFT
    gradient = ((keys >> GRADIENT_SHIFT) & ((1 << GRADIENT_BITS) - 1)) - GRADIENT_OFFSET
    mass = (keys >> MASS_SHIFT) & ((1 << MASS_BITS) - 1)
    return speed, gradient, mass


def centres(keys: np.ndarray, widths: ClassWidths) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Class centres of state keys: speed [m/s], gradient [%], mass [kg]."""
    speed, gradient, mass = decode(keys)
    return speed * widths.speed_mps, gradient * widths.gradient_pct, mass * widths.mass_kg
