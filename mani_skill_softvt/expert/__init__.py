"""The scripted expert: pick-and-place waypoints (pick_place) joined by mplib motion planning (planner)."""
