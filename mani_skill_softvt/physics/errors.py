"""What the simulation raises, apart from the simulators: code that only handles a blow-up (the
rollout, the LeRobot env, the calibration's grasp script) imports this, not the FEM (Warp, Newton)."""


class SimulationInstabilityError(RuntimeError):
    """The FEM simulation blew up (NaN/inf, or nodes faster than anything in a tabletop scene)."""
