"""Policies that misbehave on purpose, loaded by the evaluator as ``misbehaving_policies:Class``
(the worker processes import this module by name: pytest puts tests/ on their sys.path).

``Misbehaving`` picks its misbehaviour from the episode's index in the soft-cube ID protocol, so
that one evaluation covers them all; ``CRUSH_TARGET_ENV`` gives the crushing episode its target
(a policy sees no object pose; the test reads it from the env, as an evaluator could).
"""

import os
import signal

import numpy as np

from mani_skill_softvt.data.seeds import id_seed
from mani_skill_softvt.evaluation.policies import HoldPolicy
from mani_skill_softvt.contracts.actions import ee_action

TASK = 3
CRUSH_TARGET_ENV = "SOFTVT_TEST_CRUSH_TARGET"  # "x,y,z_top" of the object at the crushing episode
BEHAVIOURS = ("raise_in_act", "nan", "wrong_shape", "strings", "kill_own_process", "raise_in_reset", "crush")


def behaviour_of(seed: int) -> str:
    return BEHAVIOURS[[id_seed(TASK, i) for i in range(len(BEHAVIOURS))].index(seed)]


def crush_chunk(target_top: np.ndarray, call: int) -> np.ndarray:
    """Closed fingers 10 cm above the object's top for four chunks, then 10 cm into it."""
    x, y, top = target_top
    z = top + 0.10 if call <= 4 else top - 0.10
    return np.stack([ee_action(np.array([x, y, z]), 1.0)] * 8)


class Misbehaving(HoldPolicy):
    name = "misbehaving"

    def reset(self, instruction, seed):
        super().reset(instruction, seed)
        self.behaviour, self.calls = behaviour_of(seed), 0
        if self.behaviour == "raise_in_reset":
            raise KeyError("no such checkpoint")

    def act(self, obs):
        self.calls += 1
        b = self.behaviour
        if b == "crush":
            return crush_chunk(np.array([float(v) for v in os.environ[CRUSH_TARGET_ENV].split(",")]), self.calls)
        if self.calls < 3:  # behave for two chunks first
            return super().act(obs)
        if b == "raise_in_act":
            raise ZeroDivisionError("deliberate failure in act")
        if b == "nan":
            return np.full((8, 7), np.nan, np.float32)
        if b == "wrong_shape":
            return np.zeros((8, 6), np.float32)
        if b == "strings":
            return [["up"] * 7]
        if b == "kill_own_process":
            os.kill(os.getpid(), signal.SIGKILL)
        raise AssertionError(b)


class Crusher(HoldPolicy):
    """Closes the gripper above ``target_top`` (x, y, z of the object's top) and pushes down."""

    name = "crusher"

    def __init__(self, target_top):
        self.target_top, self.calls = np.asarray(target_top, np.float64), 0

    def reset(self, instruction, seed):
        self.calls = 0

    def act(self, obs):
        self.calls += 1
        return crush_chunk(self.target_top, self.calls)


class SmallCameras(HoldPolicy):
    """Asks the evaluator for 32x24 cameras (``camera_size``), checks that it sees them and ends
    the episode at its first step with a NaN action (a recorded policy error naming the sizes)."""

    name = "small_cameras"
    camera_size = (24, 32)

    def act(self, obs):
        sizes = sorted({tuple(obs["sensor_data"][c]["rgb"].shape[1:3]) for c in ("base_camera", "hand_camera")})
        if sizes != [self.camera_size]:
            raise ValueError(f"cameras seen at {sizes}")
        return np.full_like(super().act(obs), np.nan)
