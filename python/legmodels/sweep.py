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
column a parameter (the value the leg had: the spec's where the design does not set it),
one a measure, the task's text columns (``DesignSummary``'s ``not_computed``: why a
measure is not a number), and ``error`` ("" or why the design failed: a design that does
not assemble is a row with its reason, never a lost batch). ``pandas.DataFrame(table)``
makes a frame of it.

The engine is Dask's ``distributed`` (a ``Client``: its scheduler reruns the batches of a
worker that dies), or any executor whose ``submit(fn, *args)`` returns a
``concurrent.futures.Future`` (``ProcessPoolExecutor``; Ray through ``ray.remote`` and
``ObjectRef.future()``, see docs/python.md). A batch carries the model's name, the task
(pickled: Dask pickles functions defined in a script by value, functions imported from a
module of the user's by reference, so that module must be importable on the workers) and
its designs' parameters by name.
"""

from __future__ import annotations

import concurrent.futures
import itertools
import math
import numbers
import operator
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
    text_columns = ("not_computed",)
    OPTIONS = ("torque_limit", "speed_limit", "body_mass", "nodes", "motor_range", "slice")

    def __init__(self, **options: Any):
        unknown = sorted(set(options) - set(self.OPTIONS))
        if unknown:
            raise TypeError(f"DesignSummary takes {', '.join(self.OPTIONS)}; not {', '.join(unknown)}")
        self.options = options

    def __call__(self, leg) -> dict:
        row = leg.design_summary(**self.options)
        why = row.pop("not_computed")
        row["not_computed"] = "; ".join(f"{k}: {v}" for k, v in why.items())
        return row

    def __repr__(self) -> str:
        return f"DesignSummary({', '.join(f'{k}={v!r}' for k, v in self.options.items())})"


class Rollout:
    """A simulation of each design from its assembled home pose at rest: ``steps`` steps of
    ``dt`` under the leg's ``simulate`` keywords (``torque``, ``controller``, ``setpoint``,
    ``amplitude``, ``frequency``, ``phase``, ``kp``, ``kd``, ``torque_limit``, ``method``,
    ``project``: the same for every design). Gives the total energy (kinetic plus
    potential, J) at the start and the end, the largest closure residual (m or rad) and
    where the foot ends: ``foot_forward`` (x), ``foot_height`` (the vertical: y in the
    plane, z in space) and ``foot_lateral`` (y of a spatial leg; NaN on a planar one)."""

    columns = ("energy_start", "energy_end", "closure_residual_max", "foot_forward", "foot_height", "foot_lateral")
    OPTIONS = ("torque", "controller", "setpoint", "amplitude", "frequency", "phase", "kp", "kd", "torque_limit", "method", "project")

    def __init__(self, steps: int, dt: float, **simulate: Any):
        unknown = sorted(set(simulate) - set(self.OPTIONS))
        if unknown:
            raise TypeError(f"Rollout takes the simulate keywords {', '.join(self.OPTIONS)}; not {', '.join(unknown)}")
        self.steps, self.dt, self.simulate = steps, dt, simulate

    def __call__(self, leg) -> dict[str, float]:
        q0 = leg.assembled_home()
        run = leg.simulate(q0, np.zeros(leg.nq), self.steps, self.dt, **self.simulate)
        foot = leg.foot_position(run["q"][-1])
        residual = np.asarray(run["closure_residual"])
        return {
            "energy_start": float(run["energy"][0]),
            "energy_end": float(run["energy"][-1]),
            "closure_residual_max": float(np.max(np.abs(residual))) if residual.size else 0.0,
            "foot_forward": float(foot[0]),
            "foot_height": float(foot[-1]),
            "foot_lateral": float(foot[1]) if len(foot) == 3 else float("nan"),
        }

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


def _result(task, leg) -> dict:
    """The task's result on ``leg``: numbers as floats, its declared text columns as str."""
    out = task(leg)
    if not isinstance(out, Mapping):
        raise TypeError(f"the task returned {type(out).__name__}, not a dict of numbers")
    text = getattr(task, "text_columns", ())
    result = {}
    for key, value in out.items():
        if key in text:
            result[key] = str(value)
        elif isinstance(value, numbers.Real) or (isinstance(value, np.ndarray) and value.shape == () and value.dtype.kind in "fiub"):
            result[key] = float(value)
        else:
            raise TypeError(f"the task's `{key}` is {type(value).__name__} {value!r:.60}, not a number")
    return result


def run_batch(model, task: Callable, batch: Sequence[tuple[int, Mapping[str, float]]]):
    """Runs ``task`` on each ``(index, parameters)`` of ``batch`` (on a worker): a list of
    ``(index, the leg's parameters, result dict or None, error)``. A design that fails is
    its own row's error (a Rust panic too)."""
    cls = _leg_class(model)
    rows = []
    for index, params in batch:
        leg = None
        try:
            leg = cls(**params)
            rows.append((index, leg.params, _result(task, leg), ""))
        except (KeyboardInterrupt, SystemExit):
            raise
        except BaseException as e:  # noqa: BLE001 (any design's failure is its row's reason)
            rows.append((index, None if leg is None else leg.params, None, f"{type(e).__name__}: {e}"))
    return rows


def _is_dask(client) -> bool:
    distributed = sys.modules.get("distributed")
    return distributed is not None and isinstance(client, distributed.Client)


def _workers(client) -> int:
    """The engine's threads: a Dask cluster's (waiting for a first worker), a pool's."""
    if _is_dask(client):
        client.wait_for_workers(1)
        return max(1, sum(w.get("nthreads", 1) for w in client.scheduler_info().get("workers", {}).values()))
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
) -> np.recarray:
    """Runs ``task`` on the leg ``model`` (a spec name or class) with each design's
    parameters, in batches of ``batch_size`` designs, and returns the table (module doc).

    ``client``: None runs here, serially, a design at a time (the reference every engine
    equals); a Dask ``distributed.Client`` submits each batch to its cluster (a batch
    whose worker died is rerun by the scheduler, up to its
    ``distributed.scheduler.allowed-failures``, 3 by default); any other executor gets
    ``submit(run_batch, model, task, batch)``. A batch the engine gives up on (its worker
    died every time, a broken pool) is rows with that reason; the other batches' rows are
    kept. ``batch_size`` defaults to the designs spread over four batches a worker thread,
    at most 256 a batch (a batch of 12 ms designs amortizes Dask's per-task cost from about
    16 designs: docs/python.md). ``progress`` (default: when stderr is a terminal) writes a
    progress line."""
    designs = [dict(d) for d in designs]
    cls = _leg_class(model)  # an unknown model fails here, not on every worker
    if isinstance(task, type):
        raise TypeError(f"`task` is the class {task.__name__}: give an instance, {task.__name__}(…)")
    if not callable(task):
        raise TypeError(f"`task` must be callable (a leg → a dict of numbers), got {task!r}")
    # A parameter named like a measure (or `index`, `error`) would lose the table at the end.
    named = set(getattr(task, "columns", ())) | set(getattr(task, "text_columns", ())) | _RESERVED
    clash = sorted(named & {name for d in designs for name in d})
    if clash:
        raise ValueError(f"parameters named like the table's own columns: {', '.join(clash)}")
    n = len(designs)
    if batch_size is None:
        batch_size = 1 if client is None else min(256, max(1, math.ceil(n / (4 * _workers(client)))))
    try:
        batch_size = operator.index(batch_size)
    except TypeError:
        raise ValueError(f"`batch_size` must be a positive integer, got {batch_size!r}") from None
    if batch_size < 1:
        raise ValueError(f"`batch_size` must be a positive integer, got {batch_size!r}")
    indexed = list(enumerate(designs))
    batches = [indexed[i : i + batch_size] for i in range(0, n, batch_size)]
    bar = _Bar(len(batches), n, sys.stderr.isatty() if progress is None else progress)
    rows: list = []
    if client is None:
        for batch in batches:
            rows.extend(run_batch(model, task, batch))
            bar.tick(len(batch))
    else:
        if _is_dask(client):
            from distributed import as_completed

            tag = uuid.uuid4().hex[:8]
            futures = [client.submit(run_batch, model, task, batch, key=f"legmodels-sweep-{tag}-{b}", pure=False) for b, batch in enumerate(batches)]
        else:
            as_completed = concurrent.futures.as_completed
            futures = [client.submit(run_batch, model, task, batch) for batch in batches]
        which = {id(f): b for b, f in enumerate(futures)}
        try:
            for future in as_completed(futures):
                batch = batches[which[id(future)]]
                try:
                    part = future.result()
                except (KeyboardInterrupt, SystemExit):
                    raise
                except BaseException as e:  # noqa: BLE001 (the engine gave the batch up)
                    part = [(i, None, None, f"the engine lost this design's batch: {type(e).__name__}: {e}") for i, _ in batch]
                rows.extend(part)
                bar.tick(len(part))
        finally:
            for future in futures:
                future.cancel()
    return _table(cls, designs, rows, task)


_RESERVED = {"index", "error"}


def _table(cls, designs, rows, task) -> np.recarray:
    """The rows in the designs' order: index, parameters, measures, text, error."""
    rows = sorted(rows, key=lambda r: r[0])
    if [r[0] for r in rows] != list(range(len(designs))):
        raise RuntimeError("the engine lost or repeated designs: the table is not complete")
    parameters = list(dict.fromkeys(name for d in designs for name in d))
    spec = cls().params
    text = list(getattr(task, "text_columns", ()))
    columns = list(getattr(task, "columns", ()))
    # Every measure any row gave, the task's declared ones first; one an undeclared
    # measure's name takes from a parameter or the table is the column `result_<name>`.
    taken = set(parameters) | _RESERVED | set(text)
    names = {c: c for c in columns}
    for r in rows:
        for key in r[2] or {}:
            if key not in names and key not in text:
                name = key
                while name in taken or name in names.values():
                    name = f"result_{name}"
                names[key] = name
    columns = list(names)
    dtype = [("index", np.int64)] + [(p, np.float64) for p in parameters] + [(names[c], np.float64) for c in columns] + [(t, object) for t in text] + [("error", object)]
    table = np.recarray(len(rows), dtype=dtype)
    for i, (index, params, result, error) in enumerate(rows):
        table["index"][i] = index
        for p in parameters:
            # The value the leg had; a design the engine lost shows what it asked for.
            value = (params or {}).get(p, designs[index].get(p, spec.get(p, np.nan)))
            try:
                table[p][i] = float(value)
            except (TypeError, ValueError):
                table[p][i] = np.nan
        for c in columns:
            table[names[c]][i] = np.nan if result is None else result.get(c, np.nan)
        for t in text:
            table[t][i] = "" if result is None else result.get(t, "")
        table["error"][i] = error
    return table
