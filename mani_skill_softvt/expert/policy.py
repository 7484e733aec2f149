"""The scripted expert as a policy of the package's contract (privileged: it plans on the env).

The evaluation runs it as the ``expert`` / ``expert_cartesian`` policies; the motion-planning
solution (:func:`mani_skill_softvt.expert.solution.solve`) runs it to the end of its plan. Its
closure is drawn from the env's calibrated envelope with the episode seed, unless given.
"""

from __future__ import annotations

import numpy as np

from ..contracts.policy import Policy
from .pick_place import DEFAULT_PLANNER, PLANNERS, draw_closure, mode_actions, plan_pick_place


class ScriptedExpertPolicy(Policy):
    """The scripted pick-and-place expert, closure drawn from the calibrated envelope (privileged).

    ``act`` returns the plan's next ``chunk`` actions in the env's control mode; once the plan is
    exhausted (``done``) it holds the last action.
    """

    name = "scripted_expert"
    privileged = True  # plans on the simulator: the rollout binds it to the env

    def __init__(self, chunk: int = 8, planner: str | None = None, closure: float | None = None,
                 strict: bool = False):
        planner = planner or DEFAULT_PLANNER
        if planner not in PLANNERS:
            raise ValueError(f"unknown expert planner '{planner}'; choose one of {PLANNERS}")
        self.chunk = chunk
        self.planner = planner
        self.fixed_closure = closure  # None: drawn per episode
        self.strict = strict  # mplib only: no Cartesian fallback
        self.env = None
        self.plan = None

    def bind(self, env) -> None:
        """The rollout hands the built-in expert (and only it) the env it plans on."""
        self.env = env

    def reset(self, instruction: str, seed: int | None) -> None:
        # The env's card: the one the DSR scorer and the dense reward read too.
        self.closure = (draw_closure(self.env.unwrapped.calibration_card, 0 if seed is None else int(seed))
                        if self.fixed_closure is None else self.fixed_closure)
        self.plan = plan_pick_place(self.env, self.closure, self.planner, strict=self.strict)
        self.name = f"scripted_expert[{self.plan.planner}]"  # the planner that actually ran (receipts)
        self._actions = (a for _, a in mode_actions(self.env, self.plan))  # in the env's control mode
        self._last = None
        self._advance()

    def _advance(self) -> None:
        """Compute the next action one ahead (the plan's actions do not depend on the steps), so that
        ``done`` is known after the last one; an error (a Cartesian plan's IK in joint space) is
        kept and raised by the ``act`` whose chunk would hold that action."""
        try:
            self._next, self._error = next(self._actions, None), None
        except Exception as e:  # noqa: BLE001 - raised in act(), at the step it belongs to
            self._next, self._error = None, e

    @property
    def done(self) -> bool:
        """The plan's actions are all handed out."""
        return self._next is None and self._error is None

    def act(self, obs) -> np.ndarray:
        out = []
        while len(out) < self.chunk and (self._next is not None or self._error is not None):
            if self._error is not None:  # the chunk that holds it fails as a whole
                raise self._error
            out.append(self._next)
            self._advance()
        if not out:  # plan finished: hold the last action
            out = [self._last]
        self._last = out[-1]
        return np.stack(out)


class CartesianExpertPolicy(ScriptedExpertPolicy):
    """The scripted expert with straight-line Cartesian moves instead of mplib's planned paths."""

    name = "scripted_expert_cartesian"

    def __init__(self, chunk: int = 8):
        super().__init__(chunk, planner="cartesian")
