"""Scripted policies: the pick-and-place expert (pick_place waypoints joined by mplib motion
planning, planner) and the calibration's grasp-lift-hold script (grasp_script)."""
