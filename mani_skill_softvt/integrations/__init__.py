"""What joins SoftVT to other projects' tools, one folder each:

- ``maniskill/``: ManiSkill's motion-planning runner and ``replay_trajectory`` on SoftVT tasks, and
  its own Diffusion Policy baseline's checkpoints as a SoftVT policy;
- ``lerobot/``: the LeRobot v3.0 dataset export and a SoftVT task as ``lerobot-eval`` steps it (the
  plugin that registers it with LeRobot is its own distribution, ``plugins/lerobot_env_softvt``);
- ``openpi/``: policies served over openpi's websocket protocol, and a server for ours.

The core library (physics, assets, tactile, tasks, expert, calibration, data, evaluation) imports
none of them: each plugs in through the library's contracts (observations, the policy contract,
the policy-kind entry points).
"""
