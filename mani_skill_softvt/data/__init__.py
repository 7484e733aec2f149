"""Demonstration data: seed ranges (seeds), the on-disk layout of a demo set (demo_set), episodes in
ManiSkill's trajectory format with their evaluator stream (trajectory), ManiSkill's episode recorder
with that stream (record). Making them is :mod:`mani_skill_softvt.demonstrations`; the LeRobot export is
:mod:`mani_skill_softvt.integrations.lerobot.export`."""
