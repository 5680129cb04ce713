"""Substrates: what happens to a node once it is deposited (physics.md §5).

A substrate decides which DOFs of a deposited node stay free, how many deposited nodes
must stay in the solve, and whether deposited edges reorient after a step. The simulator
(``deposition.py``) calls these hooks; the substrate owns no state of the rod.
"""

from __future__ import annotations

from dataclasses import dataclass

from .rod.stepper import Rod


@dataclass(frozen=True)
class FlatSticky:
    """Flat sticky substrate (static coils): a deposited node is fixed in x, y and z.

    A frictionless flat substrate gives no coils; stickiness stands in for roughness.
    Only the last ``keep_deposited`` deposited nodes influence the free rod (the bending
    stencil of node c-1 reaches back to c-2), so older ones leave the solve.
    """

    name: str = "flat"
    keep_deposited: int = 2

    def deposit(self, rod: Rod, node: int) -> None:
        """Project node onto y = 0, stop it, and fix all three coordinates."""
        i = 4 * node
        rod.q[i + 1] = 0.0
        rod.u[i : i + 3] = 0.0
        rod.fixed[i : i + 3] = 1

    def after_step(self, rod: Rod, n_deposited: int) -> None:
        """Nothing moves on a sticky substrate."""


Substrate = FlatSticky  # the stepped substrate joins this union in the serpentine issue
