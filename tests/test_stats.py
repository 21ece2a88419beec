"""so101.stats: the one percentile every printed figure uses (so101 bench, so101 reach)."""

from __future__ import annotations

import math

import pytest

from so101 import stats


def test_percentile_interpolates():
    assert stats.percentile([1, 2, 3, 4, 5], 0.5) == 3
    assert stats.percentile([0, 10], 0.99) == pytest.approx(9.9)
    assert math.isnan(stats.percentile([], 0.5))
