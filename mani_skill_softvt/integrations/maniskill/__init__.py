"""ManiSkill's tools on SoftVT tasks: the motion-planning runner (``motionplanning``), its
``replay_trajectory`` with SoftVT's action conversions (``replay``), and checkpoints of ManiSkill's
own Diffusion Policy baseline evaluated as SoftVT policies (``diffusion_policy``)."""
