"""Moved to :mod:`softvt_campaign.studies`, the campaign's distribution beside the library (``campaign/``,
``pip install -e campaign``; ``scripts/setup.sh`` installs it). An alias for one release
(:mod:`mani_skill_softvt.campaign_alias`)."""

from ..campaign_alias import moved_path

__path__ = moved_path("studies")
