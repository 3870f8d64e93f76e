"""Batch means: the standard error of the mean of an autocorrelated series (wall pressures, flow
rates), whose samples are not independent, so the naive sd / sqrt(n) understates it."""
from __future__ import annotations

import numpy as np

#: fewest samples of a series whose mean gets a batch-means error (5 batches of 2)
MIN_BATCH_SAMPLES = 10


def batch_means_stderr(values, batches: int | None = None) -> tuple[float, int]:
    """Standard error of the mean of an autocorrelated series by batch means; (stderr, batches).

    The series is cut into b contiguous batches of m = n // b samples (the first n - b m samples
    are dropped: a window's start is nearest its transient) and SE = std(batch means, ddof=1) /
    sqrt(b). b = ``batches``, else 10 from 40 samples on and 5 from 10 to 39 samples; fewer than
    10 samples (or fewer than 2 batches): (NaN, 0). Valid when a batch is much longer than the
    series' correlation time (for an AR(1) series of coefficient phi, m >> (1 + phi) / (1 - phi))."""
    x = np.asarray(values, float)
    x = x[np.isfinite(x)]
    n = len(x)
    b = batches if batches is not None else (10 if n >= 40 else 5 if n >= MIN_BATCH_SAMPLES else 0)
    if b < 2 or n < b:
        return float("nan"), 0
    m = n // b
    means = x[n - b * m:].reshape(b, m).mean(axis=1)
    return float(means.std(ddof=1) / np.sqrt(b)), int(b)
