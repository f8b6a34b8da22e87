"""Tiny helpers shared by the benchmark scripts: best-of-N timing and a text table."""

from __future__ import annotations

import time


def best_time(fn, repeat: int = 5, clock=time.perf_counter) -> float:
    """Smallest time of ``repeat`` calls, in seconds (the least disturbed run).

    ``clock``: wall time by default; ``time.process_time`` measures the CPU
    time of this process, which other jobs on a shared machine disturb less.
    """
    times = []
    for _ in range(repeat):
        start = clock()
        fn()
        times.append(clock() - start)
    return min(times)


def print_table(title: str, header: list[str], rows: list[list]) -> None:
    cells = [header] + [[str(c) for c in row] for row in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(header))]
    print(f"\n{title}")
    for k, row in enumerate(cells):
        print("  ".join(c.rjust(w) for c, w in zip(row, widths)))
        if k == 0:
            print("  ".join("-" * w for w in widths))
