"""Shared fixtures: the repository, and the Rust command-line evaluator the Python results
are compared with (`legs eval --json`, the runtime's own output, built by cargo)."""

import json
import os
import pathlib
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def legs():
    """Path of the `legs` binary (LEGS_BINARY, else built with cargo)."""
    path = os.environ.get("LEGS_BINARY")
    if not path:
        subprocess.run(
            ["cargo", "build", "--quiet", "-p", "xtask", "--features", "models", "--bin", "legs"],
            cwd=ROOT,
            check=True,
        )
        target = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
        path = str(target / "debug" / "legs")
    return path


def rust_eval(legs, model, q, qd, u=None, derivatives=False):
    """The Rust runtime's terms at a state (`legs eval MODEL --q … --json`)."""
    args = [legs, "eval", model, "--q", ",".join(repr(float(x)) for x in q), "--qd", ",".join(repr(float(x)) for x in qd), "--json"]
    if u is not None:
        args += ["--u", ",".join(repr(float(x)) for x in u)]
    if derivatives:
        args.append("--derivatives")
    out = subprocess.run(args, capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)
