"""The benchmarks (pytest-benchmark), marked slow: `pytest -m slow tests/bench` times them
(`--benchmark-disable` runs each function once, untimed, checking what it returns)."""


def timed_median(benchmark) -> float | None:
    """The median of a benchmark's timed rounds, s; None where benchmarks are off
    (`--benchmark-disable`), which run the function once and time nothing."""
    stats = benchmark.stats
    return None if stats is None else stats.stats.median
