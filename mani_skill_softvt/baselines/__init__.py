"""Moved to :mod:`softvt_campaign.baselines`, the campaign's distribution beside the library (``campaign/``,
``pip install -e campaign``; ``scripts/setup.sh`` installs it). This package is an alias for one
release: its module path is the campaign's folder, so ``python -m mani_skill_softvt.baselines.<module>``
and imports from it keep working (a module imported by both paths is loaded twice: use the new one)."""

try:
    import softvt_campaign.baselines as _moved
except ImportError as err:  # the library alone: say where the code went
    raise ImportError("mani_skill_softvt.baselines moved to softvt_campaign.baselines, the campaign's distribution: install "
                      "it with 'pip install -e campaign' from the repository root (scripts/setup.sh does)") from err

__path__ = list(_moved.__path__)
