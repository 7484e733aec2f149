"""The paper's Diffusion Policy baselines (appendix "Baseline Training Details").

- :mod:`.config`: ``DPConfig``, the variants (vo-c, vt-c, vo-b, vt-b) and the ``paper`` / ``cpu`` presets;
- :mod:`.features`: what the policy sees of a step (pure functions, shared by training and evaluation);
- :mod:`.networks`: image encoders and the conditional 1-D U-Net;
- :mod:`.model`: the diffusion model (normalisers, loss, sampling);
- :mod:`.dataset`: training windows from rendered demonstrations;
- :mod:`.train`: ``python -m softvt_campaign.baselines.train`` (progress, checkpoints, resume);
- :mod:`.agent`: a trained ``policy.pt`` as an evaluation policy (``evaluate --policy <policy.pt>``).
"""
