"""Demonstration data: seed ranges (seeds), the on-disk layout of a demo set (demo_set), episodes in
ManiSkill's trajectory format with their evaluator stream (trajectory), the LeRobot v3.0 export (lerobot)."""
