"""Generated closed-chain leg models in Python: one class per spec (``legmodels.Minitaur``,
…), ``legmodels.models`` (spec name → class), the runtime's exceptions, and
:mod:`legmodels.sweep` (design sweeps and randomized rollouts, serial or on a cluster)."""

from ._legmodels import *  # noqa: F401,F403 (the classes, `models`, the exceptions)
from . import sweep  # noqa: F401,E402
