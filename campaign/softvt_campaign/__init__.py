"""The SoftVTBench campaign: the Diffusion Policy baselines and the studies of them.

A sibling distribution of ``mani-skill-softvt`` (``pip install -e campaign``; ``scripts/setup.sh``
installs it beside the library), as ManiSkill keeps its baselines in ``examples/`` apart from the
library a user installs. It uses the library and the library never imports it:

- :mod:`.baselines`: the paper's Diffusion Policy variants, their training (``softvt-train``) and
  the trained ``policy.pt`` as an evaluation policy, registered as the library's ``diffusion_policy``
  policy kind (entry point ``mani_skill_softvt.policy_kinds``);
- :mod:`.studies`: the campaign's reports (``softvt-report``, ``softvt-ood-report``,
  ``softvt-findings``) and studies, each named for what it shows;
- :mod:`.fingerprints`: the baselines' fingerprint cases (inference and training), beside the
  library's (``scripts/fingerprint.py`` runs both).
"""

# First: the library pins the numerics (mani_skill_softvt/provenance/numerics.py) before numpy or torch load, so a
# campaign command run on its own (softvt-train, python -m softvt_campaign...) computes the same bits.
import mani_skill_softvt  # noqa: F401,E402
