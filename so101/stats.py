"""Percentiles, one definition for every figure the project prints: numpy's default, linear
interpolation between the two nearest ranks (p99 of [0, 10] is 9.9)."""

from __future__ import annotations

import math
from typing import Iterable

import numpy as np


def percentile(values: Iterable[float], fraction: float) -> float:
    """The `fraction` quantile (0..1) of `values` by linear interpolation; NaN for no values."""
    samples = list(values)
    return float(np.quantile(samples, fraction)) if samples else math.nan


def summary(values: Iterable[float], scale: float = 1.0) -> dict[str, float]:
    """p50, p99, mean and max of `values` times `scale`, and how many there were (`count`)."""
    scaled = [value * scale for value in values]
    return {
        "p50": percentile(scaled, 0.50), "p99": percentile(scaled, 0.99),
        "mean": sum(scaled) / len(scaled) if scaled else math.nan,
        "max": max(scaled) if scaled else math.nan, "count": len(scaled),
    }
