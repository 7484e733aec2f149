"""The contracts: the vocabulary the env, the policies, the data files and the evaluator share.

- ``policy.py``        what a policy is to the evaluator (``reset``, ``act``, ``privileged``)
- ``observations.py``  the observation modes, keys and camera size (one type, :class:`CameraSize`)
- ``actions.py``       the control modes, the gripper's action encodings and the robot base frame

Each imports no simulator, so a policy, a converter or a file reader needs none of ManiSkill's
machinery to speak them.
"""

from .policy import Policy, is_privileged  # noqa: F401  (what a user's policy subclasses)
