"""Shaping reward terms for learning on a small budget (issue #16 item 2), off by default.

- ``conflict``: -(1 - t / T) every step the agent is on a collision course: some body (another
  agent, a parked vehicle, a pedestrian) keeping its velocity would come nearer than half the
  two widths plus a margin within T seconds, t being the time of that closest approach; the
  nearest-in-time such body counts. Parameters ``[T [s], margin [m]]``, default ``[2.0, 0.5]``.

Select with ``LinearReward({..., "conflict": 0.05})`` or Hydra ``+reward.terms.conflict=0.05``
(``+reward.terms.conflict={weight:0.05,args:[3.0,0.5]}`` for other parameters). Kernels:
_sim/shaping.pyx; NumPy reference: selfplaydrive/testing/shaping_terms.py; docs/rewards.md.
"""

from __future__ import annotations

from selfplaydrive.rewards.components import KernelTerm

CONFLICT_ARGS = (2.0, 0.5)  # horizon T [s], margin [m]


def shaping_terms() -> tuple[KernelTerm, ...]:
    """The shaping terms as registry entries (the kernels are imported here, at first use)."""
    from selfplaydrive._sim import shaping as kernels

    addresses = kernels.shaping_term_addresses()
    return (
        KernelTerm(
            "conflict",
            int(addresses["conflict"]),
            CONFLICT_ARGS,
            "builtin",
            "R = -(1 - t/T) while a body keeping its velocity comes within half the two widths + margin "
            "at time t <= T (args: T [s], margin [m])",
            kernels,
        ),
    )
