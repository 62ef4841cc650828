"""What the cross-checks share: the generated model's terms at a state, from `legs eval --json`."""

import json
import subprocess


def ours(legs, model, q, qd, assemble=False, project=False, u=None, stance=False):
    """`legs eval MODEL --q … --qd … --json` (with `--assemble`, q and qd are the motors';
    with `--project`, q and qd are moved onto the closures first; `u`, the motor torques,
    for `qdd`; with `stance`, every contact held too: `stance`, and with `--project` qd
    moved onto the held contacts)."""
    args = [legs, "eval", model, "--q", ",".join(repr(float(x)) for x in q), "--qd", ",".join(repr(float(x)) for x in qd), "--json"]
    if u is not None:
        args += ["--u", ",".join(repr(float(x)) for x in u)]
    if assemble:
        args.append("--assemble")
    if project:
        args.append("--project")
    if stance:
        args.append("--stance")
    out = subprocess.run(args, capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"{model}: legs eval failed: {out.stderr.strip()}")
    return json.loads(out.stdout)
