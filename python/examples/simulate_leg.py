"""Simulate a Minitaur leg tracking a foot circle and plot it (notebook-style: run the
`# %%` cells one by one in an editor, or the whole file).

    python python/examples/simulate_leg.py --out minitaur.png
"""

# %% Set-up
import argparse

import matplotlib

matplotlib.use("Agg")  # files only: runs on a machine without a display
import matplotlib.pyplot as plt
import numpy as np

import legmodels

parser = argparse.ArgumentParser()
parser.add_argument("--out", default="minitaur.png", help="the figure (PNG)")
parser.add_argument("--leg", default="minitaur", choices=sorted(legmodels.models))
args = parser.parse_args()

leg = legmodels.models[args.leg]()  # the spec's parameters; Minitaur(lower_a_mass=0.2) overrides one
print(f"{leg.name}: {leg.nq} joints, {leg.nc} closure rows, motors {[leg.joint_names[i] for i in leg.actuated]}")

# %% Start at the assembled home pose, then track a 2 cm foot circle at 2 Hz under 5 N·m limits
q0 = leg.assembled_home()
centre = leg.foot_position(q0)
dt, steps = 1e-3, 1500
run = leg.simulate(
    q0, np.zeros(leg.nq), steps, dt,
    controller="foot_feedback_linearization",
    setpoint=centre, amplitude=[0.02, 0.02], frequency=[2.0, 2.0], phase=[np.pi / 2, 0.0], kp=400.0,
    torque_limit=np.full(leg.nu, 5.0),
)
foot = np.array([leg.foot_position(q) for q in run["q"]])
t = run["t"][:, None]
circle = centre + 0.02 * np.sin(4 * np.pi * t + np.array([np.pi / 2, 0.0]))
print(f"foot error after 0.5 s: {np.abs(foot[500:] - circle[500:]).max():.2e} m")

# %% Plot: the leg at a few instants with the foot's path, the torques, the energy
fig, (ax_leg, ax_u, ax_e) = plt.subplots(1, 3, figsize=(14, 4.5))
for k in range(500, 751, 50):  # one period of the circle
    joints, tips = leg.joint_positions(run["q"][k]), leg.link_tips(run["q"][k])
    for i in range(leg.nq):
        ax_leg.plot([joints[0, i], tips[0, i]], [joints[1, i], tips[1, i]], "-o", color=plt.cm.viridis((k - 500) / 250), ms=3)
ax_leg.plot(foot[:, 0], foot[:, 1], "r-", lw=0.8, label="foot")
ax_leg.set_aspect("equal")
ax_leg.set_title(f"{leg.name}: links every 50 ms")
ax_leg.legend()
ax_u.plot(run["t"], run["u"])
ax_u.set_xlabel("t [s]")
ax_u.set_ylabel("motor torque [N m]")
ax_e.plot(run["t"], run["energy"])
ax_e.set_xlabel("t [s]")
ax_e.set_ylabel("energy [J]")
fig.tight_layout()
fig.savefig(args.out, dpi=90)
print(f"wrote {args.out}")
