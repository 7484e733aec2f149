"""The campaign's studies of the baselines, each named for what it shows (docs/baselines.md).

The library a user imports to train and run a baseline is :mod:`softvt_campaign.baselines`;
these read its policies, records and demos and write the campaign's reports:

- :mod:`.results`: the variants' ID results beside the paper's, paired comparisons, success traces;
- :mod:`.ood_results`: the OOD protocol's results beside the paper's (pooled, per condition, stiffness);
- :mod:`.closure`: a policy's commanded gripper closure over its episodes, beside the expert's draw;
- :mod:`.touch_probes`: what the tactile and camera streams carry of force and deformation (linear probes);
- :mod:`.recipe_search`: the training recipes ranked by open-loop error, then closed loop;
- :mod:`.openloop`: a trained policy's held-out open-loop action error;
- :mod:`.twin_pinch`: how rigid twins sit in the scripted pinch and what the tactile model shows of it;
- :mod:`.binary_close`: what a binary close (against the force limit) does to each object against its tolerance;
- :mod:`.findings`: the paper's four findings tested on the Object suites, each marked supported,
  contradicted or unresolved.
"""
