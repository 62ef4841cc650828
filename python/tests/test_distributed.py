"""Sweeps on an engine (legmodels.sweep): a local Dask cluster of two worker processes
gives the serial run's table bit for bit, in the same order; a worker killed mid-sweep
loses and repeats no design (the scheduler reruns its batch, checked by the attempts'
log); the command line's `analyze --sweep` and the distributed path agree; a design that
fails is a row with its reason; every class and instance pickles."""

import json
import os
import pathlib
import signal
import subprocess
import sys

import numpy as np
import pytest

import legmodels
from legmodels.sweep import DesignSummary, Rollout, grid, run_batch, sample, sweep

distributed = pytest.importorskip("distributed")
import cloudpickle  # noqa: E402 (a dependency of distributed)

ROOT = pathlib.Path(__file__).resolve().parents[2]

# The test's own tasks travel to the workers by value (the workers cannot import this file).
cloudpickle.register_pickle_by_value(sys.modules[__name__])


@pytest.fixture(scope="module")
def client():
    """Two worker processes of one thread each, as on a 2-core machine."""
    from distributed import Client, LocalCluster

    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None, silence_logs=40)
    c = Client(cluster)
    yield c
    c.close()
    cluster.close()


def float_bits(table, columns):
    """The float columns as their bit patterns (NaN payloads and signs included)."""
    return {c: np.ascontiguousarray(table[c]).view(np.uint64).tolist() for c in columns}


def assert_same(a, b):
    """Equal tables: the float columns bit for bit, the text columns by value (an object
    column's bytes are pointers)."""
    assert a.dtype == b.dtype
    floats = [n for n in a.dtype.names if a.dtype[n] == np.float64]
    texts = [n for n in a.dtype.names if a.dtype[n] == object]
    assert "error" in texts
    assert a["index"].tolist() == b["index"].tolist()
    assert float_bits(a, floats) == float_bits(b, floats)
    for t in texts:
        assert a[t].tolist() == b[t].tolist(), t


def minitaur_designs(n):
    return grid(lower_a_length_x=np.linspace(0.16, 0.26, n), lower_b_length_x=np.linspace(0.16, 0.26, n))


def test_grid_and_sample_lay_designs_out():
    g = grid(a=[1, 2], b=[3, 4, 5])
    assert g == [{"a": 1, "b": 3}, {"a": 1, "b": 4}, {"a": 1, "b": 5}, {"a": 2, "b": 3}, {"a": 2, "b": 4}, {"a": 2, "b": 5}]
    s = sample(1000, seed=7, x=(0.5, 2.0))
    xs = np.array([d["x"] for d in s])
    assert xs.min() >= 0.5 and xs.max() < 2.0 and abs(xs.mean() - 1.25) < 0.05
    assert sample(5, seed=7, x=(0.5, 2.0)) == s[:5]
    with pytest.raises(ValueError, match="low <= high"):
        sample(3, x=(2.0, 1.0))


def test_serial_rows_are_the_leg_methods_own():
    """A row of the table is `design_summary` of the leg built from its parameters; its
    measures are those of the other methods (design_measures, impact_mitigation, workspace)."""
    designs = minitaur_designs(2)
    task = DesignSummary(nodes=30, torque_limit=2.0, speed_limit=30.0)
    table = sweep("minitaur", designs, task)
    for row, d in zip(table, designs):
        leg = legmodels.Minitaur(**d)
        direct = leg.design_summary(nodes=30, torque_limit=2.0, speed_limit=30.0)
        for c in DesignSummary.columns:
            assert np.float64(row[c]).tobytes() == np.float64(direct[c]).tobytes(), c
        q = leg.assembled_home()
        m = leg.design_measures(q, 2.0, 30.0)
        assert direct["condition"] == m["condition"]
        assert direct["passive_rank"] == m["passive_rank"]
        assert direct["foot_rank"] == m["foot_rank"]
        ws = leg.workspace(2.0, 30.0, nodes=30)
        assert direct["workspace_area_m2"] == ws["area"]
        assert direct["impact_mitigation"] == leg.impact_mitigation(q, body_mass=10 * sum(leg.get(n) for n in leg.parameter_names if n.endswith("_mass")))


def test_a_failing_design_is_a_row_with_its_reason():
    designs = [{"lower_a_length_x": 0.2}, {"lower_a_length_x": 5.0}, {"lower_a_length_x": -1.0, "no_such": 1.0}, {"lower_b_length_x": 0.22}]
    table = sweep("minitaur", designs, DesignSummary(nodes=20))
    # A parameter a design leaves out is the spec's value, as the leg had it.
    spec = legmodels.Minitaur().params
    assert table["lower_b_length_x"][0] == spec["lower_b_length_x"]
    assert table["lower_a_length_x"][3] == spec["lower_a_length_x"]
    assert table["index"].tolist() == [0, 1, 2, 3]
    assert table["error"][0] == "" and table["error"][3] == ""
    assert table["error"][1].startswith("AssemblyError")  # the links cannot close at home
    assert "no_such" in table["error"][2]
    assert np.isnan(table["workspace_area_m2"][1]) and np.isfinite(table["workspace_area_m2"][0])
    assert np.isnan(table["no_such"][[0, 1, 3]]).all() and table["no_such"][2] == 1.0


def test_the_cluster_equals_the_serial_run_bit_for_bit(client):
    designs = minitaur_designs(6) + [{"lower_a_length_x": 5.0, "lower_b_length_x": 0.2}]
    task = DesignSummary(nodes=24)
    serial = sweep("minitaur", designs, task)
    assert (serial["error"] == "").sum() == 36
    for batch_size in (1, 5, 64):
        assert_same(sweep("minitaur", designs, task, client=client, batch_size=batch_size), serial)
    # Any executor: the standard library's process pool gives the same.
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(2) as pool:
        assert_same(sweep("minitaur", designs, task, client=pool, batch_size=4), serial)


def test_randomized_rollouts_on_the_cluster(client):
    designs = sample(12, seed=3, lower_a_mass=(0.05, 0.2), upper_a_mass=(0.05, 0.2))
    task = Rollout(200, 1e-3)
    serial = sweep("minitaur", designs, task)
    assert (serial["error"] == "").all()
    # Passive from rest with no damping: the energy is kept (RK4, projected).
    assert np.allclose(serial["energy_end"], serial["energy_start"], rtol=0, atol=1e-6)
    assert (serial["closure_residual_max"] < 1e-9).all()
    assert_same(sweep("minitaur", designs, task, client=client, batch_size=3), serial)


class KillOnce:
    """A task whose worker dies (SIGKILL) the first time it reaches the design `victim`;
    every attempt is logged (pid, the design's two parameters)."""

    def __init__(self, inner, victim, marker, log):
        self.inner, self.victim, self.marker, self.log = inner, victim, marker, log
        self.columns, self.text_columns = inner.columns, inner.text_columns

    def __call__(self, leg):
        design = (leg.get("lower_a_length_x"), leg.get("lower_b_length_x"))
        with open(self.log, "a") as f:
            f.write(f"{os.getpid()} {design[0]!r} {design[1]!r}\n")
        if design == self.victim and not os.path.exists(self.marker):
            pathlib.Path(self.marker).touch()
            os.kill(os.getpid(), signal.SIGKILL)
        return self.inner(leg)


def test_a_worker_killed_mid_batch_loses_and_repeats_nothing(client, tmp_path):
    designs = grid(lower_a_length_x=np.linspace(0.16, 0.26, 8), lower_b_length_x=[0.2, 0.21])
    task = DesignSummary(nodes=16)
    serial = sweep("minitaur", designs, task)
    # The third design of the third batch of four: two of its batch have run when it dies.
    victim = (designs[10]["lower_a_length_x"], designs[10]["lower_b_length_x"])
    killer = KillOnce(task, victim, str(tmp_path / "killed"), str(tmp_path / "attempts"))
    table = sweep("minitaur", designs, killer, client=client, batch_size=4)
    assert (tmp_path / "killed").exists(), "the worker was not killed"
    assert_same(table, serial)
    attempts = {}
    for line in (tmp_path / "attempts").read_text().splitlines():
        pid, a, b = line.split()
        attempts.setdefault((float(a), float(b)), []).append(int(pid))
    runs = {i: len(attempts[(d["lower_a_length_x"], d["lower_b_length_x"])]) for i, d in enumerate(designs)}
    # The killed batch (designs 8–11) ran up to the victim, then whole again elsewhere.
    assert [runs[i] for i in (8, 9, 10, 11)] == [2, 2, 2, 1]
    # Any other batch ran whole once, or twice where its result was still on the worker
    # that died (Dask recomputes a result lost with its worker); the table has each once.
    for b in (0, 1, 3):
        assert {runs[i] for i in range(4 * b, 4 * b + 4)} in ({1}, {2}), runs
    pids = attempts[victim]
    assert pids[0] != pids[1], "the victim's rerun was in the process that died"


def test_a_batch_the_engine_gives_up_is_rows_with_the_reason(tmp_path):
    """A design that kills its worker breaks a process pool: its batch and those not yet
    done are rows saying so; the batches done before are kept."""
    from concurrent.futures import ProcessPoolExecutor

    designs = minitaur_designs(3)
    task = DesignSummary(nodes=12)
    serial = sweep("minitaur", designs, task)
    victim = (designs[6]["lower_a_length_x"], designs[6]["lower_b_length_x"])
    killer = KillOnce(task, victim, str(tmp_path / "killed"), str(tmp_path / "attempts"))
    with ProcessPoolExecutor(1) as pool:
        table = sweep("minitaur", designs, killer, client=pool, batch_size=1)
    assert table["index"].tolist() == list(range(9))
    lost = [e.startswith("the engine lost this design's batch: BrokenProcessPool") for e in table["error"]]
    assert lost[6] and not any(lost[:6])
    done = ~np.array(lost)
    for c in DesignSummary.columns:
        assert float_bits(table[done], [c]) == float_bits(serial[done], [c])
    assert np.isnan(table["workspace_area_m2"][6])
    # A lost design still shows the parameters it asked for.
    assert table["lower_a_length_x"][6] == victim[0]


def test_the_command_line_sweep_and_the_cluster_agree(client, legs, tmp_path):
    out = tmp_path / "analyze"
    subprocess.run(
        [legs, "analyze", "minitaur", "--sweep", "lower_a_length_x,lower_b_length_x=0.16:0.26:4", "--nodes", "40", "--out", str(out)],
        cwd=ROOT,
        check=True,
        capture_output=True,
    )
    report = json.loads((out / "analysis.json").read_text())
    rows = report["designs"]
    assert len(rows) == 4
    designs = [dict(r["parameters"]) for r in rows]
    table = sweep("minitaur", designs, DesignSummary(nodes=40), client=client, batch_size=1)
    compared = 0
    for row, r in zip(table, rows):
        for c in DesignSummary.columns:
            cli = r["table"][c]
            if cli is None:  # null: not computed or not finite
                assert not np.isfinite(row[c]), c
            else:
                assert row[c] == cli, (c, row[c], cli)
                compared += 1
    assert compared >= 4 * 8


def test_measures_that_are_not_numbers_say_why():
    """Where a measure is not a number its row says why (`not_computed`), as analysis.json
    does: a one-motor linkage has no workspace grid, and a leg whose motors do not span
    its foot no vertical speed."""
    table = sweep("rssr_linkage", [{}], DesignSummary(nodes=12))
    assert np.isnan(table["workspace_area_m2"][0]) and table["error"][0] == ""
    assert "workspace_area_m2: " in table["not_computed"][0]
    row = legmodels.models["minitaur"]().design_summary(nodes=12)
    assert row["not_computed"] == {} or set(row["not_computed"]) <= {"singularity_distance_m"}


def test_a_tasks_results_are_checked_per_design():
    """A task's results become floats on the worker: a text, an array or None is that
    design's error, named; measures only some rows give are columns all the same."""

    def mixed(leg):
        length = leg.get("lower_a_length_x")
        if length < 0.17:
            return {"a": 1.0}
        if length < 0.19:
            return {"b": np.float32(2.0), "n": 3}
        if length < 0.21:
            return {"label": "tall"}
        if length < 0.23:
            return {"foot": leg.foot_position(leg.home())}
        return None

    table = sweep("minitaur", grid(lower_a_length_x=[0.16, 0.18, 0.2, 0.22, 0.24]), mixed)
    assert table.dtype.names == ("index", "lower_a_length_x", "a", "b", "n", "error")
    assert table["a"][0] == 1.0 and table["b"][1] == 2.0 and table["n"][1] == 3.0 and np.isnan(table["a"][1])
    assert table["error"][2] == "TypeError: the task's `label` is str 'tall', not a number"
    assert table["error"][3].startswith("TypeError: the task's `foot` is ndarray")
    assert table["error"][4] == "TypeError: the task returned NoneType, not a dict of numbers"


def test_bad_arguments_are_refused():
    assert sweep("minitaur", [], DesignSummary()).shape == (0,)
    assert sweep("minitaur", [{}], DesignSummary(nodes=8), batch_size=np.int64(2))["error"][0] == ""
    with pytest.raises(TypeError, match="give an instance, DesignSummary"):
        sweep("minitaur", [{}], DesignSummary)
    with pytest.raises(TypeError, match="not nodez"):
        DesignSummary(nodez=20)
    with pytest.raises(TypeError, match="not controler"):
        Rollout(10, 1e-3, controler="pd_gravity")
    with pytest.raises(ValueError, match="named like the table's own columns: condition, error"):
        sweep("minitaur", [{"error": 1.0, "condition": 2.0}], DesignSummary())


def test_a_measure_named_like_a_parameter_keeps_both():
    """An undeclared measure that takes a parameter's or the table's name gets a column of
    its own (`result_<name>`): nothing computed is lost at the end."""
    table = sweep("minitaur", [{"lower_a_length_x": 0.2}], lambda leg: {"lower_a_length_x": 7.0, "error": 8.0, "index": 9.0})
    assert table["lower_a_length_x"][0] == 0.2
    assert (table["result_lower_a_length_x"][0], table["result_error"][0], table["result_index"][0]) == (7.0, 8.0, 9.0)
    assert table["error"][0] == "" and table["index"][0] == 0
    with pytest.raises(ValueError, match="no model `minitaurr`"):
        sweep("minitaurr", [{}], DesignSummary())
    with pytest.raises(ValueError, match="batch_size"):
        sweep("minitaur", [{}], DesignSummary(), batch_size=0)
    with pytest.raises(TypeError, match="callable"):
        sweep("minitaur", [{}], 3)
    assert run_batch("minitaur", DesignSummary(nodes=2), [(0, {"lower_a_length_x": "x"})])[0][3].startswith("ValueError")


def test_every_legs_row_is_the_command_lines(legs, tmp_path):
    """`design_summary` of every leg (planar, spatial, hoppers with body joints, one-motor
    linkages, legs its motors do not determine) equals its row of `legs analyze` bit for
    bit, nulls where ours are not finite."""
    out = tmp_path / "analyze"
    models = sorted(legmodels.models)
    subprocess.run([legs, "analyze", *models, "--nodes", "12", "--out", str(out)], cwd=ROOT, check=True, capture_output=True)
    report = json.loads((out / "analysis.json").read_text())
    assert sorted(d["model"] for d in report["designs"]) == models
    kinds = set()
    for d in report["designs"]:
        leg = legmodels.models[d["model"]]()
        if "error" in d:
            with pytest.raises(legmodels.LegError):
                leg.design_summary(nodes=12)
            continue
        row = leg.design_summary(nodes=12)
        for c in legmodels.analysis_columns:
            cli = d["table"].get(c)
            if cli is None:
                assert not np.isfinite(row[c]), (d["model"], c, row[c])
                kinds.add(c)
            else:
                assert np.float64(row[c]).tobytes() == np.float64(cli).tobytes(), (d["model"], c, row[c], cli)
    # The legs include ones where measures do not apply (so the nulls were compared too).
    assert {"vertical_speed_m_s", "workspace_area_m2"} <= kinds
