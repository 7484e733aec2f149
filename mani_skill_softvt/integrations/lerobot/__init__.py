"""LeRobot: the v3.0 dataset export of rendered demos (``export``) and a SoftVT task as
``lerobot-eval`` steps it, scored as SoftVT scores it (``env``). LeRobot itself is imported only by
the plugin distribution ``lerobot_env_softvt`` (``plugins/``), which registers the env config."""
