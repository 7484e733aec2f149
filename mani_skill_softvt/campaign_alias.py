"""The one-release aliases of the campaign's old module paths (``mani_skill_softvt.baselines`` and
``.studies``, now ``softvt_campaign.baselines`` and ``.studies``, the distribution in ``campaign/``)."""


def moved_path(package: str) -> list[str]:
    """The module path of ``softvt_campaign.<package>``, for the alias package's ``__path__``: then
    ``python -m mani_skill_softvt.<package>.<module>`` runs the moved module (a module imported by
    both paths is loaded twice: use the new one)."""
    try:
        moved = __import__(f"softvt_campaign.{package}", fromlist=["__path__"])
    except ImportError as err:  # the library alone: say where the code went
        raise ImportError(f"mani_skill_softvt.{package} moved to softvt_campaign.{package}, the campaign's "
                          "distribution: install it with 'pip install -e campaign' from the repository root "
                          "(scripts/setup.sh does)") from err
    return list(moved.__path__)
