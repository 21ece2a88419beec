"""Feature statistics as LeRobot 0.4.x computes them (lerobot/datasets/compute_stats.py): per
episode over its frames, and aggregated over episodes for meta/stats.json."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from so101.dataset.video import Image

# compute_stats.py: RunningQuantileStats' quantiles and histogram bins.
QUANTILES = (0.01, 0.10, 0.50, 0.90, 0.99)
QUANTILE_KEYS = tuple(f"q{int(q * 100):02d}" for q in QUANTILES)
QUANTILE_BINS = 5000
STAT_KEYS = ("min", "max", "mean", "std", "count") + QUANTILE_KEYS

Stats = dict[str, dict[str, np.ndarray]]

def sample_indices(length: int) -> list[int]:
    """The frames of an episode whose pictures enter its image statistics (LeRobot's sample_indices)."""
    min_samples, max_samples, power = 100, 10_000, 0.75
    if length < min_samples:
        min_samples = length
    count = max(min_samples, min(int(length**power), max_samples))
    return [int(i) for i in np.round(np.linspace(0, length - 1, count)).astype(int)]


def _downsample(image: Image) -> Image:
    # auto_downsample_height_width: pictures 300 px or larger are thinned to about 150 px.
    height, width = image.shape[:2]
    if max(width, height) < 300:
        return image
    factor = int(width / 150) if width > height else int(height / 150)
    return image[::factor, ::factor]


_CHANNEL_OFFSETS = np.array([0, 256, 512], dtype=np.int32)


def image_histogram(image: Image) -> npt.NDArray[np.int64]:
    """How many pixels of each value (0-255) each channel has, after LeRobot's downsampling: (3, 256).

    Every image statistic LeRobot keeps (min, max, mean, std, its histogram quantiles) follows
    from these counts, so an episode keeps 3 kB per frame instead of its pictures."""
    pixels = _downsample(image).reshape(-1, 3).astype(np.int32) + _CHANNEL_OFFSETS
    return np.bincount(pixels.ravel(), minlength=768).reshape(3, 256).astype(np.int64)


def _histogram_quantile(counts: np.ndarray, edges: np.ndarray, target: float) -> float:
    # RunningQuantileStats._compute_single_quantile: the bin where the count passes `target`,
    # interpolated linearly within it.
    cumulative = np.cumsum(counts)
    idx = int(np.searchsorted(cumulative, target))
    if idx == 0:
        return float(edges[0])
    if idx >= len(cumulative):
        return float(edges[-1])
    before = cumulative[idx - 1]
    in_bin = cumulative[idx] - before
    if in_bin == 0:
        return float(edges[idx])
    return float(edges[idx] + (target - before) / in_bin * (edges[idx + 1] - edges[idx]))


def _quantiles(column: np.ndarray, weights: np.ndarray | None = None) -> list[float]:
    """LeRobot's quantiles of one column: a 5000-bin histogram between its min and max.

    `column` keeps its dtype (float32 actions give float32 bin edges, as in LeRobot); `weights`
    counts each value's occurrences (the image histograms)."""
    if column.dtype == np.bool_:  # what np.histogram would make of it, said here rather than warned about
        column = column.astype(np.uint8)
    if weights is None:
        low, high, total = column.min(), column.max(), len(column)
    else:
        present = column[weights > 0]
        low, high, total = present.min(), present.max(), int(weights.sum())
    edges = np.linspace(low - 1e-10, high + 1e-10, QUANTILE_BINS + 1)
    counts, _ = np.histogram(column, bins=edges, weights=weights)
    return [_histogram_quantile(counts, edges, q * total) for q in QUANTILES]


def vector_stats(values: np.ndarray) -> dict[str, np.ndarray]:
    """One numeric feature's statistics over an episode: values (frames,) or (frames, n).

    min and max keep the values' dtype (ints stay ints in the JSON); mean and std are exact
    (float64), where LeRobot's float32 running sums lose digits; quantiles are LeRobot's."""
    as_rows = values.reshape(len(values), -1)
    wide = as_rows.astype(np.float64)
    mean = wide.mean(axis=0)
    stats: dict[str, np.ndarray] = {
        "min": as_rows.min(axis=0),
        "max": as_rows.max(axis=0),
        "mean": mean,
        "std": wide.std(axis=0),
        "count": np.array([len(values)], dtype=np.int64),
    }
    if len(values) < 2:  # _compute_basic_stats: too few for a histogram, the mean stands in
        per_column = [list(mean) for _ in QUANTILES]
    else:
        by_column = [_quantiles(as_rows[:, i]) for i in range(as_rows.shape[1])]
        per_column = [[column[k] for column in by_column] for k in range(len(QUANTILES))]
    for key, column_values in zip(QUANTILE_KEYS, per_column):
        stats[key] = np.array(column_values, dtype=np.float64)
    return stats


def image_stats(histograms: list[np.ndarray]) -> dict[str, np.ndarray]:
    """An episode's picture statistics from its frames' histograms (image_histogram), as LeRobot
    computes them: over the pixels of sample_indices' frames, per channel, in [0, 1], shaped
    (3, 1, 1); count is the number of frames sampled.

    std is the true one: LeRobot 0.4.x squares uint8 pixels in uint8 (compute_stats.py
    RunningQuantileStats.update), which wraps around and leaves its image std 0 or near it."""
    chosen = sample_indices(len(histograms))
    counts = np.sum([histograms[i] for i in chosen], axis=0).astype(np.float64)  # (3, 256)
    levels = np.arange(256, dtype=np.float64)
    totals = counts.sum(axis=1)
    mean = (counts * levels).sum(axis=1) / totals
    variance = (counts * (levels - mean[:, None]) ** 2).sum(axis=1) / totals
    present = counts > 0
    stats: dict[str, np.ndarray] = {
        "min": np.array([levels[row].min() for row in present]),
        "max": np.array([levels[row].max() for row in present]),
        "mean": mean,
        "std": np.sqrt(variance),
        "count": np.array([len(chosen)], dtype=np.int64),
    }
    # np.arange(256) as integers, so the bin edges are float64 as for LeRobot's uint8 pixels.
    by_channel = [_quantiles(np.arange(256), counts[c]) for c in range(3)]
    for k, key in enumerate(QUANTILE_KEYS):
        stats[key] = np.array([by_channel[c][k] for c in range(3)])
    return {key: value if key == "count" else (value / 255.0).reshape(3, 1, 1) for key, value in stats.items()}


def aggregate_feature_stats(stats_list: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """LeRobot's aggregate_feature_stats: count-weighted means, pooled variance, quantiles weighted by count."""
    means = np.stack([s["mean"] for s in stats_list])
    variances = np.stack([s["std"] ** 2 for s in stats_list])
    counts = np.stack([s["count"] for s in stats_list])
    total_count = counts.sum(axis=0)
    while counts.ndim < means.ndim:
        counts = np.expand_dims(counts, axis=-1)
    total_mean = (means * counts).sum(axis=0) / total_count
    delta_means = means - total_mean
    total_variance = ((variances + delta_means**2) * counts).sum(axis=0) / total_count
    aggregated = {
        "min": np.min(np.stack([s["min"] for s in stats_list]), axis=0),
        "max": np.max(np.stack([s["max"] for s in stats_list]), axis=0),
        "mean": total_mean,
        "std": np.sqrt(total_variance),
        "count": total_count,
    }
    for key in QUANTILE_KEYS:
        if all(key in s for s in stats_list):
            aggregated[key] = (np.stack([s[key] for s in stats_list]) * counts).sum(axis=0) / total_count
    return aggregated


def aggregate_stats(stats_list: list[Stats]) -> Stats:
    """LeRobot's aggregate_stats: per feature, over every stats dict that has it."""
    keys = [key for stats in stats_list for key in stats]
    return {key: aggregate_feature_stats([stats[key] for stats in stats_list if key in stats])
            for key in dict.fromkeys(keys)}


def stats_to_json(stats: Stats) -> dict[str, dict[str, Any]]:
    return {key: {name: value.tolist() for name, value in feature.items()} for key, feature in stats.items()}


def stats_from_json(data: dict[str, dict[str, Any]]) -> Stats:
    return {key: {name: np.array(value) for name, value in feature.items()} for key, feature in data.items()}
