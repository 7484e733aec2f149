"""mani_skill_softvt: deformation-aware visuo-tactile ManiSkill3 tasks."""
