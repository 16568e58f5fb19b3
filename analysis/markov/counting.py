"""Transition counts of the 2D chain (physics.md, Markov section), stored sparsely and additive.

Counting works on 1 Hz samples (`resample_1hz`). Before counting, each sample is put into its
classes and made physically consistent (`enforce_physics`):

* a standstill run keeps the gradient class of its first sample (the place where the truck
  stopped): no gradient change at standstill;
* a driving run (between two standstills) keeps one mass class, the median of its samples; the
  stop before it ends with that mass and the stop after it starts with it: mass changes only
  between two standstill samples.

Any transition that still breaks these rules (a one-sample stop between two masses) is dropped and
counted in ``n_dropped``. Only observed transitions are stored: memory grows with the data, not
with the class grid. ``counts_a + counts_b`` is the chain of both data sets (a fleet is a sum).
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..errors import UserError
from ..runs import equal_runs
from ..stop_mass import mass_at_stops
from . import classes as cls

QUANTITIES = ("speed_mps", "gradient_pct", "accel_mps2", "mass_kg")
NEEDED = ("time_s", "speed_mps", "gradient_pct", "mass_kg")
GAP_S = 2.0


class CountingError(UserError):
    pass


def resample_1hz(signals: pd.DataFrame, gap_s: float = GAP_S) -> pd.DataFrame:
    """Signals at whole seconds: speed and gradient linear, mass held (it changes in steps).

    Mass missing inside a stop is filled (`mass_at_stops`). Samples with ``valid`` False or any
    missing value are left out; where that leaves more than ``gap_s`` [s] without a usable sample,
    the data is split into segments (column ``segment``) and no transition is counted across the
    split. Shorter dropouts (a lost CAN frame, a stalled batch) are interpolated over.
    """
    missing = [c for c in NEEDED if c not in signals.columns]
    if missing:
        raise CountingError(f"signals lack column(s) {', '.join(missing)} needed for the driving cycle")
    frame = signals[list(NEEDED)].astype(float)
    frame["mass_kg"] = mass_at_stops(frame["time_s"].to_numpy(), frame["speed_mps"].to_numpy(),
                                     frame["mass_kg"].to_numpy())
    usable = np.isfinite(frame.to_numpy()).all(axis=1)
    if "valid" in signals.columns:
        usable &= signals["valid"].fillna(False).to_numpy(bool)
    rows_all = np.flatnonzero(usable)
    time = frame["time_s"].to_numpy()[rows_all]
    columns = {c: frame[c].to_numpy()[rows_all] for c in ("speed_mps", "gradient_pct", "mass_kg")}
    split = np.diff(time) > gap_s
    edges = np.concatenate([[0], np.flatnonzero(split) + 1, [len(rows_all)]])
    pieces = []
    for a, b in zip(edges[:-1], edges[1:]):
        t = time[a:b]
        grid = np.arange(np.ceil(t[0]), np.floor(t[-1]) + 0.5, 1.0) if b > a else np.zeros(0)
        if grid.size == 0:
            continue
        held = np.clip(np.searchsorted(t, grid, side="right") - 1, 0, len(t) - 1)
        pieces.append((grid, np.interp(grid, t, columns["speed_mps"][a:b]),
                       np.interp(grid, t, columns["gradient_pct"][a:b]), columns["mass_kg"][a:b][held],
                       np.full(len(grid), len(pieces))))
    if not pieces:
        raise CountingError("no usable samples: speed, gradient and mass are all needed at the same time")
    joined = [np.concatenate(part) for part in zip(*pieces)]
    return pd.DataFrame(dict(zip(("time_s", "speed_mps", "gradient_pct", "mass_kg", "segment"), joined)))


def enforce_physics(speed_class, gradient_class, mass_class):
    """Classes of one segment with no gradient change at standstill and mass changes only at
    standstill (module docstring); returns new (gradient_class, mass_class) arrays."""
    gradient_class = np.array(gradient_class, dtype=np.int64)
    mass_class = np.array(mass_class, dtype=np.int64)
    moving = np.asarray(speed_class) > 0
    if moving.size == 0:
        return gradient_class, mass_class
    starts, ends = equal_runs(moving)
    run_mass = {}
    for i, (a, b) in enumerate(zip(starts, ends)):
        if moving[a]:
            run_mass[i] = int(np.round(np.median(mass_class[a:b])))
            mass_class[a:b] = run_mass[i]
        else:
            gradient_class[a:b] = gradient_class[a]
    for i, (a, b) in enumerate(zip(starts, ends)):
        if not moving[a]:
            if i - 1 in run_mass:
                mass_class[a] = run_mass[i - 1]
            if i + 1 in run_mass:
                mass_class[b - 1] = run_mass[i + 1]
    return gradient_class, mass_class


def physically_possible(from_key: np.ndarray, to_key: np.ndarray) -> np.ndarray:
    """True where a transition is possible: gradient fixed while both ends stand still, mass fixed
    unless both ends stand still."""
    v0, g0, m0 = cls.decode(from_key)
    v1, g1, m1 = cls.decode(to_key)
    standstill = (v0 == 0) & (v1 == 0)
    return np.where(standstill, g0 == g1, m0 == m1)


def moments_of(values: np.ndarray) -> np.ndarray:
    """Additive moments [n, sum, sum of squares, min, max] of ``values``."""
    values = np.asarray(values, dtype=float)
    if values.size == 0:
        return np.array([0.0, 0.0, 0.0, np.inf, -np.inf])
    return np.array([values.size, values.sum(), np.square(values).sum(), values.min(), values.max()])


def add_moments(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.concatenate([a[..., :3] + b[..., :3], np.minimum(a[..., 3:4], b[..., 3:4]),
                           np.maximum(a[..., 4:5], b[..., 4:5])], axis=-1)


def statistics_of(moments: np.ndarray) -> np.ndarray:
    """(mean, std, min, max) per quantity from additive moments (population std)."""
    n = np.maximum(moments[..., 0], 1)
    mean = moments[..., 1] / n
    std = np.sqrt(np.maximum(moments[..., 2] / n - mean ** 2, 0.0))
    return np.stack([mean, std, moments[..., 3], moments[..., 4]], axis=-1)


@dataclass
class TransitionCounts:
    """Observed transitions of the chain: ``count[i]`` times ``from_key[i]`` → ``to_key[i]``.

    Sorted by (from_key, to_key), one entry per pair; ``start_key``/``start_count`` the states
    the data's segments begin in at standstill (a drive's initial stop). ``moments`` holds additive moments
    (`moments_of`) of the class-centre samples per quantity of `QUANTITIES` (acceleration from
    1 Hz differences of class-centre speeds), the measured side of the criteria.
    """

    widths: cls.ClassWidths
    from_key: np.ndarray
    to_key: np.ndarray
    count: np.ndarray
    moments: np.ndarray = field(default_factory=lambda: np.tile(moments_of([]), (len(QUANTITIES), 1)))
    n_samples: int = 0
    n_dropped: int = 0
    n_closed: int = 0
    start_key: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    start_count: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    def __len__(self) -> int:
        return len(self.count)

    def __add__(self, other: "TransitionCounts") -> "TransitionCounts":
        if not isinstance(other, TransitionCounts):
            return NotImplemented
        if other.widths != self.widths:
            raise CountingError(f"cannot add transition counts of different class widths "
                                f"({self.widths.as_dict()} and {other.widths.as_dict()}); count both with the same")
        from_key, to_key, count = _merge(np.concatenate([self.from_key, other.from_key]),
                                         np.concatenate([self.to_key, other.to_key]),
                                         np.concatenate([self.count, other.count]))
        return TransitionCounts(self.widths, from_key, to_key, count, add_moments(self.moments, other.moments),
                                self.n_samples + other.n_samples, self.n_dropped + other.n_dropped,
                                self.n_closed + other.n_closed,
                                *_merge_starts(np.concatenate([self.start_key, other.start_key]),
                                               np.concatenate([self.start_count, other.start_count])))

    def __radd__(self, other):
        return self if other == 0 else self.__add__(other)

    @property
    def statistics(self) -> np.ndarray:
        """(mean, std, min, max) of the measured data, one row per quantity of `QUANTITIES`."""
        return statistics_of(self.moments)

    @property
    def nbytes(self) -> int:
        return self.from_key.nbytes + self.to_key.nbytes + self.count.nbytes


def _merge_starts(keys, count):
    """Sum the counts of equal start keys."""
    unique, where = np.unique(keys.astype(np.int64), return_inverse=True)
    return unique, np.bincount(where, weights=count, minlength=len(unique)).astype(np.int64)


def _merge(from_key, to_key, count):
    """Sum the counts of equal (from, to) pairs; return them sorted."""
    if len(count) == 0:
        return from_key.astype(np.int64), to_key.astype(np.int64), count.astype(np.int64)
    states, inverse = np.unique(np.concatenate([from_key, to_key]), return_inverse=True)
    n = len(from_key)
    pair = inverse[:n].astype(np.int64) * len(states) + inverse[n:]
    pairs, where = np.unique(pair, return_inverse=True)
    summed = np.bincount(where, weights=count, minlength=len(pairs)).astype(np.int64)
    return states[pairs // len(states)], states[pairs % len(states)], summed


def _stops(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First and last sample index of each standstill run of a segment."""
    standstill = cls.decode(keys)[0] == 0
    starts, ends = equal_runs(standstill)
    stop = standstill[starts]
    return starts[stop], ends[stop] - 1


def closures(segments: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Closing transitions, standstill to standstill at the same gradient class: each segment's
    final stop → the first other stop like it in the following segments (cyclically, then its
    own), and the last other stop like a segment's initial stop in the preceding segments → that
    initial stop. Never within one stop, never across a gradient class."""
    by_gradient: dict[int, list[tuple[int, int, int, int]]] = {}
    finals, initials = {}, {}
    for t, keys in enumerate(segments):
        starts, ends = _stops(keys)
        gradients = cls.decode(keys[starts])[1] if starts.size else []
        for run, (first, last, gradient) in enumerate(zip(starts, ends, gradients)):
            by_gradient.setdefault(int(gradient), []).append((t, run, int(keys[first]), int(keys[last])))
        if starts.size:
            finals[t] = (len(starts) - 1, int(keys[ends[-1]]), int(gradients[-1]))
            initials[t] = (int(keys[starts[0]]), int(gradients[0]))
    times = {gradient: [stop[0] for stop in stops] for gradient, stops in by_gradient.items()}
    from_keys, to_keys = [], []
    for i, (final_run, final_key, gradient) in finals.items():
        stops, t = by_gradient[gradient], times[gradient]
        after = bisect.bisect_right(t, i)
        own = [s for s in stops[bisect.bisect_left(t, i):after] if s[1] != final_run]
        target = stops[after] if after < len(stops) else stops[0] if t[0] < i else own[0] if own else None
        if target is not None:
            from_keys.append(final_key)
            to_keys.append(target[2])
    for i, (initial_key, gradient) in initials.items():
        stops, t = by_gradient[gradient], times[gradient]
        before = bisect.bisect_left(t, i)
        own = [s for s in stops[before:bisect.bisect_right(t, i)] if s[1] != 0]
        source = stops[before - 1] if before > 0 else stops[-1] if t[-1] > i else own[-1] if own else None
        if source is not None:
            from_keys.append(source[3])
            to_keys.append(initial_key)
    return np.array(from_keys, dtype=np.int64), np.array(to_keys, dtype=np.int64)


def count_transitions(signals, widths: cls.ClassWidths | None = None, close_loops: bool = True) -> TransitionCounts:
    """Count the chain's transitions in a signals table (any rate; resampled to 1 Hz), a mapping of
    1 Hz arrays ``speed_mps`` [m/s], ``gradient_pct`` [%], ``mass_kg`` [kg] (optional ``time_s`` [s],
    ``segment``), or a list of either (one vehicle's logs, linked by ``close_loops``).

    ``close_loops`` **[choice]**: the truck's next drive starts from a standstill like the one it
    parked at (`closures`); without it, every drive's end is a dead end and, at fine mass classes,
    every payload is its own closed chain (docs/cycles.md).

    Parameters
    ----------
    signals : DataFrame, mapping of arrays, or list of them
        ``time_s`` [s], ``speed_mps`` [m/s], ``gradient_pct`` [%], ``mass_kg`` [kg].
    widths : ClassWidths, optional
        Class widths: speed [km/h], gradient [%], mass [kg]; default 1 km/h, 0.5 %, 100 kg.
    close_loops : bool
        Link each drive's end to a start from a like standstill.

    Returns
    -------
    TransitionCounts
        Sparse counts of (from state, to state), per-state moments and start counts; counts of
        several logs add up with ``+``.

    References
    ----------
    Paper §2.3: the 2D Markov chain of speed and combined gradient-and-mass classes.
    """
    widths = widths or cls.ClassWidths()
    items = signals if isinstance(signals, (list, tuple)) else [signals]
    segments, from_parts, to_parts, moment_parts = [], [], [], []
    n_samples = n_dropped = 0
    for item in items:
        frame = item if isinstance(item, pd.DataFrame) else pd.DataFrame(dict(item))
        if "time_s" not in frame.columns:
            frame = frame.assign(time_s=np.arange(len(frame), dtype=float))
        if "segment" not in frame.columns:
            frame = resample_1hz(frame)
        for _, seg in frame.groupby("segment", sort=False):
            speed_class = cls.class_index(np.clip(seg["speed_mps"].to_numpy(), 0, None), widths.speed_mps)
            gradient_class, mass_class = enforce_physics(
                speed_class, cls.class_index(seg["gradient_pct"].to_numpy(), widths.gradient_pct),
                cls.class_index(seg["mass_kg"].to_numpy(), widths.mass_kg))
            keys = cls.encode(speed_class, gradient_class, mass_class)
            possible = physically_possible(keys[:-1], keys[1:])
            from_parts.append(keys[:-1][possible])
            to_parts.append(keys[1:][possible])
            n_dropped += int((~possible).sum())
            n_samples += len(keys)
            segments.append(keys)
            speed, gradient, mass = cls.centres(keys, widths)
            moment_parts.append(np.stack([moments_of(speed), moments_of(gradient), moments_of(np.diff(speed)),
                                          moments_of(mass)]))
    n_closed = 0
    if close_loops:
        closing_from, closing_to = closures(segments)
        from_parts.append(closing_from)
        to_parts.append(closing_to)
        n_closed = len(closing_from)
    moments = moment_parts[0]
    for part in moment_parts[1:]:
        moments = add_moments(moments, part)
    from_all, to_all = np.concatenate(from_parts), np.concatenate(to_parts)
    from_key, to_key, count = _merge(from_all, to_all, np.ones(len(from_all), dtype=np.int64))
    starts = [keys[0] for keys in segments if cls.decode(keys[:1])[0][0] == 0]
    start_key, start_count = _merge_starts(np.array(starts, dtype=np.int64), np.ones(len(starts), np.int64))
    return TransitionCounts(widths, from_key, to_key, count, moments, n_samples, n_dropped, n_closed,
                            start_key, start_count)
