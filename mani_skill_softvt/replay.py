"""ManiSkill's ``replay_trajectory`` on SoftVT trajectories: ``python -m mani_skill_softvt.replay``.

ManiSkill's tool imports only ``mani_skill.envs``, so it cannot make a third-party env by itself.
This entry registers the SoftVT envs, then hands every flag to ManiSkill's own replay unchanged
(``--traj-path``, ``-o``, ``-c``, ``--use-env-states``, ``--use-first-env-state``, ``--save-traj``,
``--save-video``, ``-n`` ...; ``--help`` lists them)::

    python -m mani_skill_softvt.replay --traj-path demos/sample/object_soft/task3.h5 \\
        --use-env-states -o rgb+tactile --save-traj

Output goes beside the input as ``<name>.<obs_mode>.<control_mode>.physx_cpu.h5`` and ``.json``,
ManiSkill's naming.
"""

from __future__ import annotations

import multiprocessing as mp
import sys


def main(argv: list[str] | None = None) -> None:
    import mani_skill_softvt  # noqa: F401  (registers the SoftVT envs before ManiSkill makes one)
    from mani_skill.trajectory import replay_trajectory

    args = replay_trajectory.parse_args(argv)
    replay_trajectory.main(args)


if __name__ == "__main__":
    # ManiSkill's replay starts worker processes with -n > 1; Warp needs spawn (as ManiSkill's own tool does).
    mp.set_start_method("spawn", force=True)
    main(sys.argv[1:])
