"""The physics settings that shape a soft grasp, as one frozen config (SI units).

An env is built with one (``gym.make(..., physics={"newton_substeps": 8})`` overrides the
defaults; the overrides are plain values, so ManiSkill records them with the env's kwargs), its
FEM world and scene objects read that one, and its :meth:`~PhysicsConfig.signature` is what a
calibration card, a demo set and a calibration sweep record, so that anything made under other
physics is refused instead of mixed. Nothing patches module constants: a benchmark that sweeps a
setting passes a config. Values were measured on this project's 2-core CPU machines unless noted
(docs/physics.md).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

from ..provenance import EE_ORIENTATION_AXIS_ANGLE, signature_differences
from ..settings import with_overrides


@dataclass(frozen=True)
class PhysicsConfig:
    # Lockstep rate: SAPIEN and Newton both step at sim_freq, one Newton step per SAPIEN step.
    # 100 Hz with Newton substeps was unstable (15 g fingers, one-step-late contact forces).
    sim_freq: int = 240
    # Newton substeps per lockstep tick and VBD iterations per substep. VBD is a Gauss-Seidel
    # solver: with E ~ 5e4 Pa and ~8 mm elements a node's elastic stiffness is ~60x its inertia
    # m/dt^2 at 240 Hz, and under-converged iterations create spurious net forces (a resting cube
    # drifts sideways). Substepping raises m/dt^2 by substeps^2, which converges far better than
    # more iterations.
    newton_substeps: int = 4
    vbd_iterations: int = 5
    # Stiff FEM bodies (E >= stiff_modulus, e.g. hard rubber; the package's rigid twins are PhysX
    # rigid bodies and never reach Newton) get more substeps, not more iterations: a node's elastic
    # stiffness scales with E and its inertia m/h^2 with substeps^2, so x5 stiffer bodies need
    # ~sqrt(5) x the substeps to converge like the soft assets. At 4 x 10 a 20 g bun (FEM, x5 stiff)
    # held by 2 x 1 N of pad force (9x its weight at mu 0.9) still slid out during transport; at 8 x 5
    # (the same 40 sweeps per tick) it holds, and 4 x 20 holds at 1.7x the wall time (measured).
    stiff_modulus: float = 2.5e5  # Pa
    newton_substeps_stiff: int = 8
    # Friction smoothing velocity [m/s]: below it VBD's Coulomb friction is a viscous drag, so a
    # resting or held object creeps. 1e-2 let a held object creep ~1 mm/s; at 1e-3 a resting cube
    # crept 0.139 mm/s, at 1e-4 0.024 mm/s with the same cost and the calibration grasp's peak D
    # within 2 % (benchmarks/bench_vbd_schedule.py).
    friction_epsilon: float = 1e-4
    # Particle-collider contact (penalty) stiffness [N/m] and damping, per contact point.
    soft_contact_ke: float = 5.0e3
    soft_contact_kd: float = 1.0e-2
    # Contact radius of FEM nodes [m]; Newton's default (0.1 m) would make 10 cm thick skins.
    particle_radius: float = 1.0e-3
    # Contact detection margin [m].
    soft_contact_gap: float = 4.0e-3
    # Friction coefficients of the colliders (VBD mixes them with the object's own).
    finger_friction: float = 1.2  # rubber pads (the paper uses dynamic mu = 1.2 on the fingers)
    table_friction: float = 0.6

    def with_overrides(self, overrides: dict | None = None, **more) -> "PhysicsConfig":
        """This config with some settings replaced; ValueError naming a setting that is not one."""
        return with_overrides(self, "physics", overrides, **more)

    def vbd_schedule(self, youngs_moduli) -> tuple[int, int]:
        """(Newton substeps per tick, VBD iterations per substep) for a world holding bodies of these
        moduli (Pa): stiff bodies (hard rubber and up) get more substeps so that pad friction converges."""
        stiff = any(float(e) >= self.stiff_modulus for e in youngs_moduli)
        return (self.newton_substeps_stiff if stiff else self.newton_substeps), self.vbd_iterations

    def signature(self) -> dict:
        """What a card, a demo set or a sweep records of the physics it was made under: each setting
        under the name records have always carried it by (``SIM_FREQ``...), and the hand's orientation
        convention (:data:`~mani_skill_softvt.provenance.EE_ORIENTATION_AXIS_ANGLE`, a history marker)."""
        out = {f.name.upper(): float(getattr(self, f.name)) for f in fields(self)}
        return {**out, "EE_ORIENTATION_AXIS_ANGLE": EE_ORIENTATION_AXIS_ANGLE}


DEFAULT_PHYSICS = PhysicsConfig()


def physics_signature(config: PhysicsConfig = DEFAULT_PHYSICS) -> dict:
    """The signature of ``config`` (default: the package's physics)."""
    return config.signature()


def signature_mismatch(recorded, config: PhysicsConfig = DEFAULT_PHYSICS) -> list[str]:
    """Human-readable differences between a recorded signature and ``config``'s (default: the package's)."""
    return signature_differences(recorded, physics_signature(config))
