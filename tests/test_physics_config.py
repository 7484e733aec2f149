"""The physics settings are one frozen config, passed to an env, never patched (physics/config.py)."""

import json

import gymnasium as gym
import pytest

import mani_skill_softvt  # noqa: F401  (registers the envs)
from mani_skill_softvt.assets.cards import ASSET_IDS
from mani_skill_softvt.paths import CALIBRATION_DIR
from mani_skill_softvt.physics.config import DEFAULT_PHYSICS, PhysicsConfig, physics_signature
from mani_skill_softvt.tactile.config import DEFAULT_TACTILE


def test_the_signature_names_each_setting_as_every_committed_card_recorded_it():
    """The config's signature is, key for key and value for value, what the committed cards were made
    under: they stay valid (a card made under other physics is refused, calibration/cards.py)."""
    card = json.loads((CALIBRATION_DIR / f"{ASSET_IDS[0]}.json").read_text())
    assert sorted(physics_signature()) == sorted(card["physics"]) and physics_signature() == card["physics"]


def test_overrides_make_another_config_and_name_a_setting_that_is_not_one():
    stiffer = DEFAULT_PHYSICS.with_overrides({"newton_substeps": 8}, friction_epsilon=1e-3)
    assert (stiffer.newton_substeps, stiffer.friction_epsilon, stiffer.vbd_iterations) == (8, 1e-3, 5)
    assert DEFAULT_PHYSICS.newton_substeps == 4 and stiffer.signature()["NEWTON_SUBSTEPS"] == 8.0
    with pytest.raises(ValueError, match=r"\['substep'\] are not settings"):
        DEFAULT_PHYSICS.with_overrides(substep=8)
    with pytest.raises(Exception):  # frozen: nothing patches a config in place
        DEFAULT_PHYSICS.newton_substeps = 2
    # Stiff bodies get the stiff schedule, whatever the config's numbers.
    cfg = PhysicsConfig(newton_substeps=3, newton_substeps_stiff=6, vbd_iterations=2)
    assert cfg.vbd_schedule([5e4]) == (3, 2) and cfg.vbd_schedule([5e4, 1e6]) == (6, 2)


def test_an_env_runs_its_fem_world_and_gelsights_under_the_settings_it_was_given():
    """gym.make(..., physics=overrides, tactile=overrides): the FEM world and the objects take that
    physics, the GelSights that gel (tactile/config.py); an env built afterwards without overrides has
    the package's (nothing global was changed)."""
    worlds, backgrounds = [], []
    for physics, tactile in (({"newton_substeps": 2, "friction_epsilon": 1e-3, "finger_friction": 0.9},
                              {"marker_radius": 5.0, "gel_modulus": 1.2e6}), (None, None)):
        env = gym.make("SoftGraspLift-v1", obs_mode="state", asset_id=ASSET_IDS[0], physics=physics, tactile=tactile)
        try:
            env.reset(seed=0)
            u = env.unwrapped
            world = u.objects.world
            worlds.append((world.substeps, world.physics.friction_epsilon, u.physics.finger_friction,
                           u.objects.contact_radius, u.physics.signature() == physics_signature(),
                           u.tactile_config.gel_modulus))
            backgrounds.append(u.tactile_background("left"))
        finally:
            env.close()
    assert worlds[0] == (2, 1e-3, 0.9, DEFAULT_PHYSICS.particle_radius, False, 1.2e6)
    assert worlds[1] == (4, DEFAULT_PHYSICS.friction_epsilon, 1.2, DEFAULT_PHYSICS.particle_radius, True,
                         DEFAULT_TACTILE.gel_modulus)
    # The sensors drew their dots at the radius given: larger dots darken more of the gel.
    assert backgrounds[0].sum() < backgrounds[1].sum()
    with pytest.raises(ValueError, match=r"tactile settings \['gel_stiffness'\] are not settings"):
        gym.make("SoftGraspLift-v1", obs_mode="state", asset_id=ASSET_IDS[0], tactile={"gel_stiffness": 1.0})


def test_a_card_made_under_other_physics_than_the_envs_is_refused():
    """An env built with physics overrides scores DSR only with cards calibrated under them: the
    committed cards (the package's physics) are refused for it, naming the setting."""
    from mani_skill_softvt.calibration.cards import load_calibration_card

    assert load_calibration_card(ASSET_IDS[0]).g_max > 0  # the package's physics: accepted
    with pytest.raises(ValueError, match="other physics.*NEWTON_SUBSTEPS: recorded 4.0, now 2.0"):
        load_calibration_card(ASSET_IDS[0], physics=DEFAULT_PHYSICS.with_overrides(newton_substeps=2))
    with pytest.raises(TypeError, match="give a dict of overrides"):
        gym.make("SoftGraspLift-v1", obs_mode="state", asset_id=ASSET_IDS[0], physics=DEFAULT_PHYSICS)
