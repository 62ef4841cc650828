"""Designs per second of a sweep here and on a local Dask cluster of one and two workers,
in one run, and the engine's cost per task (the README's and docs/python.md's figures).

    .venv/bin/python python/benchmarks/sweep.py [--side 100] [--nodes 40]

Sweeps `side²` Minitaur designs (both lower links, 0.16–0.26 m) with analyze's row
(`DesignSummary(nodes=…)`): serially in this process, then on clusters of one and two
worker processes (one thread each), each table checked equal to the serial one bit for
bit. Then the per-task cost: designs of a task that does nothing, one design a batch, and
the same designs at batch sizes 1 to 256.
"""

import argparse
import time

import numpy as np
from distributed import Client, LocalCluster

from legmodels.sweep import DesignSummary, grid, sweep


class Nothing:
    """A task that builds the leg and returns at once: what remains is the engine's cost."""

    columns = ("one",)

    def __call__(self, leg):
        return {"one": 1.0}


def same(a, b):
    """Equal tables: floats bit for bit, text by value."""
    floats = [n for n in a.dtype.names if a.dtype[n] == np.float64]
    texts = [n for n in a.dtype.names if a.dtype[n] == object]
    return all(np.array_equal(np.ascontiguousarray(a[c]).view(np.uint64), np.ascontiguousarray(b[c]).view(np.uint64)) for c in floats) and all(a[t].tolist() == b[t].tolist() for t in texts)


def timed(f):
    started = time.perf_counter()
    out = f()
    return out, time.perf_counter() - started


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--side", type=int, default=100, help="designs per side of the grid (side² designs)")
    ap.add_argument("--nodes", type=int, default=40, help="workspace nodes per side of each design")
    a = ap.parse_args()
    values = np.linspace(0.16, 0.26, a.side)
    designs = grid(lower_a_length_x=values, lower_b_length_x=values)
    task = DesignSummary(nodes=a.nodes)
    n = len(designs)
    serial, t_serial = timed(lambda: sweep("minitaur", designs, task, progress=False))
    print(f"{n} Minitaur designs, analyze's row at {a.nodes}² nodes; {int((serial['error'] == '').sum())} assemble")
    print(f"serial, in this process: {t_serial:.1f} s, {n / t_serial:.0f} designs/s")
    rates = {}
    for workers in (1, 2):
        with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None, silence_logs=40) as cluster, Client(cluster) as client:
            client.run(lambda: __import__("legmodels"))  # workers warm: imported once
            table, t = timed(lambda: sweep("minitaur", designs, task, client=client, progress=False))
            assert same(table, serial), "the cluster's table differs from the serial one"
            rates[workers] = n / t
            batch = min(256, -(-n // (4 * workers)))
            print(f"Dask, {workers} worker{'s' if workers > 1 else ''}: {t:.1f} s, {n / t:.0f} designs/s (batches of {batch}; equal to the serial table bit for bit)")
            if workers == 2:
                few = designs[:400]
                _, t_nothing = timed(lambda: sweep("minitaur", few, Nothing(), client=client, batch_size=1, progress=False))
                print(f"engine cost per task (400 one-design tasks of nothing, 2 workers): {1e3 * t_nothing / len(few) * workers:.2f} ms of a worker's time, {1e3 * t_nothing / len(few):.2f} ms wall")
                part = designs[:512]
                for size in (1, 4, 16, 64, 256):
                    _, t_part = timed(lambda: sweep("minitaur", part, task, client=client, batch_size=size, progress=False))
                    print(f"  batch of {size:3d}: {len(part) / t_part:.0f} designs/s")
    print(f"speed-up of 2 workers over 1: {rates[2] / rates[1]:.2f}x")


if __name__ == "__main__":
    main()
