"""All streams onto one time base: bins of 1/rate on the logger's monotonic clock.

Streams are reduced block by block (so a 10-hour log never sits in memory at full rate): each
sample falls in bin ``t_mono_ns // period_ns``; a bin's value is the mean of its samples
("mean" signals) or the last sample ("last" signals: gear, switches). After all blocks, a value is
held into following empty bins for at most `hold_bins` (1.5 sample periods, never more than 1 s
for dynamic signals), and never into a bin where the logger recorded nothing: such bins are
gaps, ``valid`` False, every signal NaN.

Rows are not made for every bin between the first and the last: a silence longer than
`MAX_GAP_S` (the truck parked overnight, two logs months apart) is shortened to `KEPT_GAP_S` of
gap rows (`Grid`), so memory grows with the recorded time, not with the calendar time between logs.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from . import bin_kernels

MAX_HOLD_S = 1.0
"""No value is carried across a missing second."""
QUASI_STATIC_HOLD_S = 60.0
"""Signals that change only at stops (reported mass) are held this long between messages."""
MAX_GAP_S = 600.0
"""Silences longer than this [s] are shortened in the table (`Grid`)."""
KEPT_GAP_S = 60.0
"""Gap rows [s] kept in place of a shortened silence: longer than every hold and bridge, so no value
or transition crosses it."""


@dataclass(frozen=True)
class Grid:
    """Output rows as runs of consecutive bins: run ``i`` maps bins ``run_bins[i] …`` to rows
    ``run_rows[i] …``; between runs, a silence longer than `MAX_GAP_S` was shortened."""

    run_bins: np.ndarray
    run_rows: np.ndarray
    n: int

    @classmethod
    def uniform(cls, first_bin: int, n_bins: int) -> "Grid":
        return cls(np.array([first_bin], np.int64), np.array([0], np.int64), int(n_bins))

    @property
    def lengths(self) -> np.ndarray:
        return np.diff(np.append(self.run_rows, self.n))

    def rows_of(self, bins: np.ndarray) -> np.ndarray:
        """Row of each bin; -1 for a bin outside every run."""
        bins = np.asarray(bins, dtype=np.int64)
        run = np.searchsorted(self.run_bins, bins, side="right") - 1
        safe = np.clip(run, 0, len(self.run_bins) - 1)
        offset = bins - self.run_bins[safe]
        inside = (run >= 0) & (offset < self.lengths[safe])
        return np.where(inside, self.run_rows[safe] + offset, -1)

    def bins(self) -> np.ndarray:
        """The bin of every row."""
        return np.repeat(self.run_bins - self.run_rows, self.lengths) + np.arange(self.n, dtype=np.int64)

    def shortened(self, period_ns: int) -> list[dict]:
        """Where silences were shortened: the row after each, its time in the table [s] and the time taken out [s]."""
        lengths = self.lengths
        out = []
        for i in range(1, len(self.run_bins)):
            removed = int(self.run_bins[i] - (self.run_bins[i - 1] + lengths[i - 1]))
            out.append({"row": int(self.run_rows[i]), "time_s": self.run_rows[i] * period_ns / 1e9,
                        "removed_s": removed * period_ns / 1e9})
        return out


@dataclass
class _Stream:
    kind: str
    bins: list = field(default_factory=list)
    sums: list = field(default_factory=list)
    counts: list = field(default_factory=list)
    n: int = 0
    t_first: int | None = None
    t_last: int | None = None


class BinAccumulator:
    """Per-bin sums/counts (or last values) of named streams, fed in blocks."""

    def __init__(self, rate_hz: float):
        if not rate_hz > 0:
            raise ValueError("rate_hz must be positive")
        self.period_ns = int(round(1e9 / rate_hz))
        self.streams: dict[str, _Stream] = {}
        self._activity: list[np.ndarray] = []

    def add(self, name: str, time_ns: np.ndarray, values: np.ndarray, kind: str = "mean") -> None:
        """Add samples (time [ns, continuous monotonic], values); NaN values count as absent."""
        values = np.asarray(values, dtype=np.float64)
        time_ns = np.asarray(time_ns, dtype=np.int64)
        in_order, bins, sums, counts, kept, t0, t1 = bin_kernels.bin_in_order(time_ns, values, self.period_ns,
                                                                               kind == "last")
        if not in_order:
            bins, sums, counts, kept, t0, t1 = bin_sorting(time_ns, values, self.period_ns, kind)
        self.add_binned(name, bins, sums, counts, int(kept), int(t0), int(t1), kind)

    def add_binned(self, name: str, bins: np.ndarray, sums: np.ndarray, counts: np.ndarray, n: int,
                   t_first_ns: int, t_last_ns: int, kind: str = "mean") -> None:
        """Add samples already reduced to distinct ``bins`` (their sums or last values, and counts),
        ``n`` samples from ``t_first_ns`` to ``t_last_ns``."""
        stream = self.streams.setdefault(name, _Stream(kind))
        if n == 0:
            return
        stream.bins.append(bins)
        stream.sums.append(sums)
        stream.counts.append(counts)
        stream.n += n
        stream.t_first = t_first_ns if stream.t_first is None else min(stream.t_first, t_first_ns)
        stream.t_last = t_last_ns if stream.t_last is None else max(stream.t_last, t_last_ns)

    def mark_recorded_bins(self, bins: np.ndarray) -> None:
        """`mark_recorded` of samples whose distinct bins, ascending, are known."""
        if len(bins):
            self._activity.append(bins)

    def mark_recorded(self, time_ns: np.ndarray) -> None:
        """Note that the logger recorded something at these times (defines ``valid``)."""
        if len(time_ns):
            runs, ascending = bin_kernels.bin_runs(np.asarray(time_ns, dtype=np.int64), self.period_ns)
            self._activity.append(runs if ascending else np.unique(runs))

    def grid(self, max_gap_s: float = MAX_GAP_S, kept_gap_s: float = KEPT_GAP_S) -> Grid | None:
        """Rows for every recorded bin and the silences between them, each silence longer than
        ``max_gap_s`` [s] shortened to ``kept_gap_s`` [s]; None if nothing was recorded."""
        if not self._activity:
            return None
        recorded = np.concatenate(self._activity)
        if not np.all(recorded[1:] > recorded[:-1]):
            # sorted runs, one per block and stream: a merging sort finds them
            recorded = np.sort(recorded, kind="stable")
            recorded = recorded[np.concatenate(([True], recorded[1:] != recorded[:-1]))]
        max_gap = int(round(max_gap_s * 1e9 / self.period_ns))
        kept = int(round(kept_gap_s * 1e9 / self.period_ns))
        long_gap = np.flatnonzero(np.diff(recorded) > max_gap)
        starts = np.concatenate([recorded[:1], recorded[long_gap + 1]])
        ends = np.concatenate([recorded[long_gap] + 1 + kept, recorded[-1:] + 1])
        rows = np.concatenate([[0], np.cumsum(ends - starts)])
        return Grid(starts.astype(np.int64), rows[:-1].astype(np.int64), int(rows[-1]))

    def bin_range(self) -> tuple[int, int] | None:
        """(first bin, number of bins) covering every recorded time; None if nothing was."""
        if not self._activity:
            return None
        lo = min(int(a[0]) for a in self._activity)
        hi = max(int(a[-1]) for a in self._activity)
        return lo, hi - lo + 1

    def recorded(self, grid: Grid | int, n_bins: int | None = None, bridge_s: float = MAX_HOLD_S) -> np.ndarray:
        """Rows of ``grid`` (or bins ``grid …`` of ``n_bins``) backed by data. A silence shorter than
        ``bridge_s`` (a late batch, a scheduling stall) is not a gap: values are held across it; a
        silence of ``bridge_s`` or more stays a gap."""
        grid = grid if isinstance(grid, Grid) else Grid.uniform(grid, n_bins)
        n_bins = grid.n
        mask = np.zeros(n_bins, dtype=bool)
        for bins in self._activity:
            rows = grid.rows_of(bins)
            mask[rows[rows >= 0]] = True
        bridge_bins = int(round(bridge_s * 1e9 / self.period_ns))
        edges = np.flatnonzero(np.diff(np.concatenate([[1], mask.astype(np.int8), [1]])))
        for start, stop in zip(edges[::2], edges[1::2]):
            if 0 < start and stop < n_bins and stop - start < bridge_bins:
                mask[start:stop] = True
        return mask

    def series(self, name: str, grid: Grid | int, n_bins: int | None = None) -> np.ndarray:
        """Per-row value of one stream on ``grid`` (or bins ``grid …`` of ``n_bins``), NaN where it
        has no sample, before holding."""
        grid = grid if isinstance(grid, Grid) else Grid.uniform(grid, n_bins)
        n_bins = grid.n
        stream = self.streams[name]
        out = np.full(n_bins, np.nan)
        if not stream.bins:
            return out
        bins = grid.rows_of(np.concatenate(stream.bins))
        sums, counts = np.concatenate(stream.sums), np.concatenate(stream.counts)
        # a GPS fix placed at its epoch can fall before the first recorded bin, or into a shortened silence
        inside = bins >= 0
        bins, sums, counts = bins[inside], sums[inside], counts[inside]
        if stream.kind == "last":
            out[bins] = sums
            return out
        total = np.bincount(bins, sums, n_bins)
        count = np.bincount(bins, counts, n_bins)
        with np.errstate(invalid="ignore", divide="ignore"):
            out = np.where(count > 0, total / count, np.nan)
        return out

    def sample_period_s(self, name: str) -> float:
        """Mean interval between samples of a stream [s] (inf for fewer than two)."""
        stream = self.streams[name]
        if stream.n < 2:
            return float("inf")
        return (stream.t_last - stream.t_first) / (stream.n - 1) / 1e9


def bin_sorting(time_ns: np.ndarray, values: np.ndarray, period_ns: int, kind: str):
    """`bin_kernels.bin_in_order` for samples out of time order: (bins, sums, counts, kept, t_first, t_last)."""
    keep = np.isfinite(values)
    time_ns, values = time_ns[keep], values[keep]
    if len(values) == 0:
        return None, None, None, 0, 0, 0
    bins = time_ns // period_ns
    if kind == "last":
        order = np.argsort(time_ns, kind="stable")[::-1]
        unique, first = np.unique(bins[order], return_index=True)
        sums, counts = values[order][first], np.ones(len(unique))
    else:
        unique, inverse = np.unique(bins, return_inverse=True)
        sums = np.bincount(inverse, values, len(unique))
        counts = np.bincount(inverse, minlength=len(unique)).astype(np.float64)
    return unique, sums, counts, len(values), time_ns.min(), time_ns.max()


def hold(values: np.ndarray, recorded: np.ndarray, limit_bins: int) -> np.ndarray:
    """Carry each value forward into at most ``limit_bins`` empty bins, never into unrecorded bins."""
    out = values.copy()
    if limit_bins > 0:
        out = pd.Series(out).ffill(limit=limit_bins).to_numpy(copy=True)
        # A hold must not jump a gap: bins after an unrecorded bin only keep their own values.
        gap_id = np.cumsum(~recorded)
        source_gap = pd.Series(np.where(np.isfinite(values), gap_id, np.nan)).ffill().to_numpy()
        crossed = np.isfinite(out) & ~np.isfinite(values) & (source_gap != gap_id)
        out[crossed] = np.nan
    out[~recorded] = np.nan
    return out


def interpolate(values: np.ndarray, recorded: np.ndarray, limit_bins: int) -> np.ndarray:
    """Linear between two values at most ``limit_bins`` apart (a quantity that changes smoothly,
    sampled slower than the table: GPS speed), else `hold`; never into unrecorded bins."""
    out = hold(values, recorded, limit_bins)
    known = np.flatnonzero(np.isfinite(values))
    if known.size < 2:
        return out
    index = np.arange(len(values))
    before = np.maximum.accumulate(np.where(np.isfinite(values), index, -1))
    after = np.minimum.accumulate(np.where(np.isfinite(values), index, len(values))[::-1])[::-1]
    inside = (before >= 0) & (after < len(values)) & (after - before <= limit_bins) & ~np.isfinite(values)
    out[inside] = np.interp(index[inside], known, values[known])
    out[~recorded] = np.nan
    return out


def hold_bins(period_s: float, rate_hz: float, max_hold_s: float = MAX_HOLD_S) -> int:
    """Bins to hold a stream sampled every ``period_s`` [s]: 1.5 periods, capped at ``max_hold_s``."""
    if not np.isfinite(period_s):
        period_s = max_hold_s
    return int(np.ceil(min(1.5 * period_s, max_hold_s) * rate_hz))


def wall_clock_ns(grid_mono_ns: np.ndarray, pairs: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray | None:
    """Wall-clock [ns] of monotonic times from the best (first non-empty) list of clock pairs.

    The offset wall - mono is interpolated linearly between pairs and held beyond the ends, so a
    jump of the realtime clock shows as a step only where it happened.
    """
    for mono, wall in pairs:
        if len(mono) == 0:
            continue
        order = np.argsort(mono, kind="stable")
        mono, wall = np.asarray(mono, dtype=np.int64)[order], np.asarray(wall, dtype=np.int64)[order]
        offset = wall - mono
        relative = (offset - offset[0]).astype(np.float64)
        return grid_mono_ns + offset[0] + np.round(np.interp(grid_mono_ns, mono, relative)).astype(np.int64)
    return None
