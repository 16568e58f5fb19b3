"""Time stamps of samples read in batches from a sensor FIFO: a continuous sample clock.

A FIFO read returns the samples taken since the last read, not when each was taken. Stamping them
backwards from the time of the read (newest = read time) makes batches overlap whenever the read
is late relative to the sample it reports (the thread was descheduled between reading FIFO_SRC
and the clock), and the stamps would jitter with every scheduling gap.

Here each sample is the previous one plus the output data rate's period. The read bounds when the
newest sample in the FIFO was taken: not before ``before_ns - period`` (the sample after it did
not exist yet when FIFO_SRC was read at ``before_ns``) and not after ``after_ns``. While the
running clock stays inside that window nothing changes; when it leaves it (the sensor's own
oscillator is a few per cent off its nominal rate) the batch is stretched or squeezed toward the
window by at most ``max_correction`` of a period per sample, so the spacing stays within
``(1 ± max_correction) · period`` and the stamps strictly increase. After an overrun (samples lost,
how many unknown) the clock re-anchors on the window, never before the previous stamp plus one
period per sample.
"""

from __future__ import annotations


class FifoSampleClock:
    """Stamps [ns] for batches of samples at a nominal period [ns]."""

    def __init__(self, period_ns: int, max_correction: float = 0.25):
        if not 0.0 < max_correction < 1.0:
            raise ValueError("max_correction must be in (0, 1)")
        self.period_ns = int(period_ns)
        self.max_correction = max_correction
        self.last_ns: int | None = None
        self.corrections = 0
        """Batches whose spacing was stretched or squeezed toward the read window."""

    def stamps(self, n: int, before_ns: int, after_ns: int, overrun: bool = False) -> list[int]:
        """Stamps of ``n`` samples read between ``before_ns`` and ``after_ns`` (monotonic [ns])."""
        if n <= 0:
            return []
        period = self.period_ns
        low, high = before_ns - period, max(after_ns, before_ns)
        if self.last_ns is None or overrun:
            newest = (low + high) // 2
            if self.last_ns is not None:
                newest = max(newest, self.last_ns + n * period)
            out = [newest - (n - 1 - i) * period for i in range(n)]
        else:
            predicted = self.last_ns + n * period
            target = min(max(predicted, low), high)
            bound = int(self.max_correction * period * n)
            correction = min(max(target - predicted, -bound), bound)
            if correction:
                self.corrections += 1
            span = n * period + correction
            out = [self.last_ns + (i * span) // n for i in range(1, n + 1)]
        self.last_ns = out[-1]
        return out
