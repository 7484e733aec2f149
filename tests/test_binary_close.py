"""studies/binary_close.py on hand-written screening logs: what counts as a success, as within tolerance."""

import json

import pytest

from softvt_campaign.studies import binary_close as B


def _log(root, suite, task, lines, control_mode="pd_ee_pose_binary"):
    d = root / suite / f"task{task}"
    d.mkdir(parents=True, exist_ok=True)
    (root / suite / "manifest.json").write_text(json.dumps({"control_mode": control_mode}))
    (d / "qc.jsonl").write_text("".join(json.dumps(x) + "\n" for x in lines))


def test_a_binary_close_is_scored_by_the_screening_and_set_beside_the_continuous_expert(tmp_path):
    binary = [{"seed": 0, "r_max": 1.03, "problems": ["R_max 1.030 > 1"]},             # carried, squeezed past
              {"seed": 1, "r_max": 0.97, "problems": []},                              # carried within
              {"seed": 2, "r_max": 0.99, "problems": ["a tet collapsed (1 at most) in 3 states"]},
              {"seed": 3, "r_max": 0.50, "problems": ["object dropped"]},
              {"seed": 4, "r_max": 0.0, "problems": ["no steps"]},                       # no plan: not a success
              {"seed": 5, "r_max": float("nan"), "problems": ["NaN or inf in the recorded streams"]}]
    _log(tmp_path / "bin", "object_soft", 0, binary)
    _log(tmp_path / "cont", "object_soft", 0, [{"seed": s, "r_max": 0.2 + 0.1 * s, "problems": []} for s in range(6)],
         control_mode="pd_ee_pose")
    result = B.main(["--demos", str(tmp_path / "bin"), "--continuous", str(tmp_path / "cont"), "--out", str(tmp_path)])
    row = result["tasks"][0]
    assert (row["episodes"], row["successes"], row["within_tolerance"], row["dsr_successes"]) == (6, 3, 3, 1)
    assert row["r_max_range"] == (0.0, 1.03)  # the NaN left out
    assert row["continuous_r_max_median"] == pytest.approx(0.45) and row["continuous_episodes"] == 6  # seeds 0-5 only
    assert (row["continuous_successes"], row["continuous_dsr_successes"]) == (6, 6)
    assert (tmp_path / "binary_close.md").read_text().count("| 0 (") == 1


def test_a_continuous_generation_is_refused(tmp_path):
    _log(tmp_path, "object_soft", 0, [{"seed": 0, "r_max": 0.3, "problems": []}], control_mode="pd_ee_pose")
    with pytest.raises(SystemExit):
        B.main(["--demos", str(tmp_path), "--out", str(tmp_path)])


def test_the_calibration_percentile_that_would_cover_a_binary_close():
    # A sweep whose peak D grows with the closure: 0.3 never holds, from 0.4 on every repeat holds.
    records = [{"closure": g, "held": g >= 0.4, "peak_deformation": 10 * g + 0.1 * k}
               for g in (0.3, 0.4, 0.6, 0.8, 1.0) for k in range(3)]
    out = B.sweep_at_full_close(records, tau_o=9.0, peak_d=8.15)
    assert out["sweep_r_at_closure_1"] == pytest.approx(10.1 / 9.0)  # median of 10.0, 10.1, 10.2
    # 12 stable peaks, sorted: 8.1 is the 8th (rank 7 of 0-11), 8.2 the 9th; numpy's linear
    # percentile reaches 8.15 halfway between ranks 7 and 8: at 100 * 7.5 / 11.
    assert out["covering_percentile"] == pytest.approx(100 * 7.5 / 11, abs=0.01)
    import numpy as np
    peaks = [r["peak_deformation"] for r in records if r["held"]]
    assert np.percentile(peaks, out["covering_percentile"]) >= 8.15 > np.percentile(peaks, out["covering_percentile"] - 0.01)
    assert B.sweep_at_full_close(records, tau_o=9.0, peak_d=11.0)["covering_percentile"] is None  # beyond the sweep
