"""Design sweeps and randomized rollouts: one leg design a row, run here or on a cluster.

A design is a dict of parameter values by name (the spec's parameters; the rest keep the
spec's values). A task is a picklable callable that takes the leg built with them and
returns a dict of numbers: :class:`DesignSummary` (the row of ``cargo xtask analyze``'s
table, the command's numbers to the bit) and :class:`Rollout` (a simulation) are built in;
any function or object of the user's does too. :func:`sweep` runs the designs in batches
on an engine and returns one table in the designs' order, whatever the number of workers:

    import numpy as np
    from dask.distributed import Client
    from legmodels.sweep import grid, sweep, DesignSummary

    designs = grid(lower_a_length_x=np.linspace(0.16, 0.26, 100),
                   lower_b_length_x=np.linspace(0.16, 0.26, 100))
    table = sweep("minitaur", designs, DesignSummary(nodes=40))            # here, serially
    table = sweep("minitaur", designs, DesignSummary(nodes=40),
                  client=Client("tcp://scheduler:8786"))                    # on a Dask cluster

The table is a numpy record array: ``index`` (the design's place in ``designs``), one
column a parameter, one a measure, and ``error`` ("" or why the design failed: a design
that does not assemble is a row with its reason, never a lost batch).
``pandas.DataFrame(table)`` makes a frame of it.

The engine is Dask's ``distributed`` (a ``Client``: its scheduler reruns the batches of a
worker that dies), or any executor with ``submit(fn, *args)`` returning a future with
``result()`` (``concurrent.futures.ProcessPoolExecutor``; Ray through ``ray.remote`` and
``ObjectRef.future()``, see docs/python.md). Batches carry the model's name, the task and
their designs' parameters by name: nothing but numbers and names crosses the network.
"""

from __future__ import annotations

import concurrent.futures
import itertools
import math
import sys
import time
import uuid
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from . import _legmodels

__all__ = ["grid", "sample", "sweep", "run_batch", "DesignSummary", "Rollout"]


def grid(**axes: Iterable[float]) -> list[dict[str, float]]:
    """Every combination of the axes' values (the last axis varies fastest), each a design:
    ``grid(a=[1, 2], b=[3, 4])`` is ``[{a: 1, b: 3}, {a: 1, b: 4}, {a: 2, b: 3}, …]``."""
    names = list(axes)
    values = [[float(v) for v in np.atleast_1d(axes[n])] for n in names]
    return [dict(zip(names, combo)) for combo in itertools.product(*values)]


def sample(n: int, seed: int = 0, **ranges: tuple[float, float]) -> list[dict[str, float]]:
    """``n`` designs drawn uniformly from ``ranges`` (name → ``(low, high)``), reproducibly
    from ``seed`` (domain randomization: masses, lengths, gear ratios)."""
    if n < 0:
        raise ValueError(f"`n` must be a count of designs, got {n}")
    rng = np.random.default_rng(seed)
    columns = {}
    for name, bounds in ranges.items():
        low, high = (float(b) for b in bounds)
        if not (math.isfinite(low) and math.isfinite(high) and low <= high):
            raise ValueError(f"`{name}`: expected (low, high) with low <= high, got {bounds!r}")
        columns[name] = rng.uniform(low, high, n)
    return [{name: float(columns[name][i]) for name in columns} for i in range(n)]


class DesignSummary:
    """The task of ``cargo xtask analyze``: a design's row of its table (the leg's
    ``design_summary(**options)``; options as there: ``torque_limit``, ``speed_limit``,
    ``body_mass``, ``nodes``, ``motor_range``, ``slice``)."""

    columns = tuple(_legmodels.analysis_columns)

    def __init__(self, **options: Any):
        self.options = options

    def __call__(self, leg) -> dict[str, float]:
        return leg.design_summary(**self.options)

    def __repr__(self) -> str:
        return f"DesignSummary({', '.join(f'{k}={v!r}' for k, v in self.options.items())})"


class Rollout:
    """A simulation of each design from its assembled home pose at rest: ``steps`` steps of
    ``dt`` under the leg's ``simulate`` keywords (``controller``, ``setpoint``, ``kp``, …).
    Gives the energy at the start and the end, the largest closure residual and where the
    foot ends."""

    columns = ("energy_start", "energy_end", "closure_residual_max", "foot_x", "foot_y", "foot_z")

    def __init__(self, steps: int, dt: float, **simulate: Any):
        self.steps, self.dt, self.simulate = steps, dt, simulate

    def __call__(self, leg) -> dict[str, float]:
        q0 = leg.assembled_home()
        run = leg.simulate(q0, np.zeros(leg.nq), self.steps, self.dt, **self.simulate)
        foot = leg.foot_position(run["q"][-1])
        row = {
            "energy_start": float(run["energy"][0]),
            "energy_end": float(run["energy"][-1]),
            "closure_residual_max": float(np.max(np.abs(run["closure_residual"]))) if run["closure_residual"].size else 0.0,
        }
        for axis, value in zip("xyz", np.append(foot, [np.nan] * (3 - len(foot)))):
            row[f"foot_{axis}"] = float(value)
        return row

    def __repr__(self) -> str:
        return f"Rollout(steps={self.steps!r}, dt={self.dt!r}, **{self.simulate!r})"


def _leg_class(model):
    if isinstance(model, str):
        try:
            return _legmodels.models[model]
        except KeyError:
            known = ", ".join(sorted(_legmodels.models))
            raise ValueError(f"no model `{model}`; the models: {known}") from None
    if isinstance(model, type) and model in _legmodels.models.values():
        return model
    raise TypeError(f"`model` must be a spec name or a legmodels class, got {model!r}")


def run_batch(model, task: Callable, batch: Sequence[tuple[int, Mapping[str, float]]]):
    """Runs ``task`` on each ``(index, parameters)`` of ``batch`` (on a worker): a list of
    ``(index, result dict or None, error)``. A design that fails is its own row's error."""
    cls = _leg_class(model)
    rows = []
    for index, params in batch:
        try:
            result = dict(task(cls(**params)))
            rows.append((index, result, ""))
        except Exception as e:  # noqa: BLE001 (any design's failure is its row's reason)
            rows.append((index, None, f"{type(e).__name__}: {e}"))
    return rows


def _is_dask(client) -> bool:
    return type(client).__module__.split(".")[0] == "distributed" and hasattr(client, "scheduler_info")


def _workers(client) -> int:
    if _is_dask(client):
        return max(1, len(client.scheduler_info().get("workers", {})))
    return max(1, getattr(client, "_max_workers", 1) or 1)


class _Bar:
    """A progress line on stderr: batches and designs done, and the time."""

    def __init__(self, batches: int, designs: int, show: bool):
        self.batches, self.designs, self.show = batches, designs, show
        self.done_batches = self.done_designs = 0
        self.started = time.perf_counter()

    def tick(self, designs: int):
        self.done_batches += 1
        self.done_designs += designs
        if self.show:
            end = "\n" if self.done_batches == self.batches else ""
            sys.stderr.write(
                f"\rsweep: {self.done_designs}/{self.designs} designs, {self.done_batches}/{self.batches} batches, "
                f"{time.perf_counter() - self.started:.1f} s{end}"
            )
            sys.stderr.flush()


def sweep(
    model,
    designs: Iterable[Mapping[str, float]],
    task: Callable,
    client=None,
    batch_size: int | None = None,
    progress: bool | None = None,
    retries: int = 3,
) -> np.recarray:
    """Runs ``task`` on the leg ``model`` (a spec name or class) with each design's
    parameters, in batches of ``batch_size`` designs, and returns the table (module doc).

    ``client``: None runs here, serially (the reference every engine equals); a Dask
    ``distributed.Client`` submits each batch to its cluster (``retries``: reruns of a
    batch that raised; a batch whose worker died is rerun by the scheduler, up to its
    ``distributed.scheduler.allowed-failures``); any other executor gets
    ``submit(run_batch, model, task, batch)``. ``batch_size`` defaults to the designs
    spread over four batches a worker, at most 256 a batch (a batch of 7 ms designs
    amortizes an engine's per-task cost from about 16 designs: docs/python.md).
    ``progress`` (default: when stderr is a terminal) writes a progress line."""
    designs = [dict(d) for d in designs]
    _leg_class(model)  # an unknown model fails here, not on every worker
    if not callable(task):
        raise TypeError(f"`task` must be callable (a leg → a dict of numbers), got {task!r}")
    n = len(designs)
    if batch_size is None:
        workers = 1 if client is None else _workers(client)
        batch_size = n if client is None else min(256, max(1, math.ceil(n / (4 * workers))))
    if not (isinstance(batch_size, int) and batch_size >= 1):
        raise ValueError(f"`batch_size` must be a positive integer, got {batch_size!r}")
    indexed = list(enumerate(designs))
    batches = [indexed[i : i + batch_size] for i in range(0, n, batch_size)]
    bar = _Bar(len(batches), n, sys.stderr.isatty() if progress is None else progress)
    rows: list = []
    if client is None:
        for batch in batches:
            rows.extend(run_batch(model, task, batch))
            bar.tick(len(batch))
    elif _is_dask(client):
        from distributed import as_completed

        tag = uuid.uuid4().hex[:8]
        futures = [
            client.submit(run_batch, model, task, batch, key=f"legmodels-sweep-{tag}-{b}", pure=False, retries=retries)
            for b, batch in enumerate(batches)
        ]
        for future in as_completed(futures):
            part = future.result()
            rows.extend(part)
            bar.tick(len(part))
    else:
        futures = [client.submit(run_batch, model, task, batch) for batch in batches]
        for future in concurrent.futures.as_completed(futures):
            part = future.result()
            rows.extend(part)
            bar.tick(len(part))
    return _table(designs, rows, getattr(task, "columns", None))


def _table(designs, rows, columns) -> np.recarray:
    """The rows in the designs' order: index, parameters, measures, error."""
    rows = sorted(rows, key=lambda r: r[0])
    if [r[0] for r in rows] != list(range(len(designs))):
        raise RuntimeError("the engine lost or repeated designs: the table is not complete")
    parameters = list(dict.fromkeys(name for d in designs for name in d))
    if columns is None:
        first = next((r[1] for r in rows if r[1] is not None), {})
        columns = list(first)
    columns = list(columns)
    clash = set(parameters) & (set(columns) | {"index", "error"})
    if clash:
        raise ValueError(f"measure or parameter names clash: {sorted(clash)}")
    dtype = [("index", np.int64)] + [(p, np.float64) for p in parameters] + [(c, np.float64) for c in columns] + [("error", object)]
    table = np.recarray(len(rows), dtype=dtype)
    for i, (index, result, error) in enumerate(rows):
        table["index"][i] = index
        for p in parameters:
            table[p][i] = designs[index].get(p, np.nan)
        for c in columns:
            table[c][i] = np.nan if result is None else float(result.get(c, np.nan))
        table["error"][i] = error
    return table
