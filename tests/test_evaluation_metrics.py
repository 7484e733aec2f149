"""DSR metrics, Wilson intervals, rescoring: hand-computed values."""

import math

import numpy as np
import pytest

from mani_skill_softvt.calibration.stats import gripper_envelope, slip_distance
from mani_skill_softvt.evaluation.metrics import (collapsed, deformation_ratio, dsr_success, r_max, rescore_record, summarize,
                                                  tolerance_violated, wilson_interval)
from mani_skill_softvt.data.seeds import id_seed, train_seed
from mani_skill_softvt.evaluation.protocols import episodes


def _rec(success, r_max, trace_scale=1.0, collapsed_steps=0):
    return {"success": success, "r_max": r_max, "tau_o": 0.01, "rigid": False, "collapsed_steps": collapsed_steps,
            "dsr_success": dsr_success(success, r_max, collapsed_steps > 0),
            "deformation_trace": [0.0, 0.01 * r_max * trace_scale]}


def test_hand_built_records_give_hand_computed_rates_and_intervals():
    recs = [_rec(True, 0.5), _rec(True, 1.2), _rec(True, 0.9), _rec(False, 0.3), _rec(False, 2.0)]
    s = summarize(recs)
    assert s["tsr"] == pytest.approx(3 / 5) and s["dsr"] == pytest.approx(2 / 5)
    assert s["gap"] == pytest.approx(1 / 5) and s["gap_share_of_successes"] == pytest.approx(1 / 3)
    # Wilson 95 % for 3/5 by hand: centre (p + z^2/2n)/(1 + z^2/n), half-width z sqrt(p q / n + z^2/4n^2)/(1 + z^2/n).
    z, n, p = 1.959963984540054, 5, 0.6
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    assert s["tsr_ci95"] == pytest.approx((c - h, c + h))
    assert wilson_interval(0, 10)[0] == 0.0 and wilson_interval(10, 10)[1] == pytest.approx(1.0)
    # The gap is 1 violating success of 5 episodes, its share 1 of 3 successes: their own intervals.
    assert s["gap_ci95"] == wilson_interval(1, 5) and s["gap_share_ci95"] == wilson_interval(1, 3)
    assert summarize([_rec(False, 0.3)])["gap_share_ci95"] is None  # no success to take a share of


def test_dsr_never_exceeds_tsr():
    import itertools

    for combo in itertools.product([True, False], [0.2, 1.0, 1.5], repeat=2):
        recs = [_rec(combo[0], combo[1]), _rec(combo[2], combo[3])]
        s = summarize(recs)
        assert s["dsr"] <= s["tsr"]


def test_rescoring_at_the_original_tolerance_reproduces_the_dsr():
    recs = [_rec(True, 0.5), _rec(True, 1.2), _rec(False, 0.3)]
    same = [rescore_record(r, r["tau_o"]) for r in recs]
    assert summarize(same)["dsr"] == summarize(recs)["dsr"]
    looser = [rescore_record(r, 2 * r["tau_o"]) for r in recs]
    assert summarize(looser)["dsr"] == pytest.approx(2 / 3)


def test_a_collapsed_tet_is_a_violation_whatever_r_max_says():
    gentle = _rec(True, 0.5)
    pressed = _rec(True, 0.5, collapsed_steps=3)
    assert dsr_success(True, 0.5) and not dsr_success(True, 0.5, collapsed=True)
    assert not tolerance_violated(gentle) and tolerance_violated(pressed)
    assert not collapsed(dict(gentle, collapsed_steps=0)) and not collapsed(dict(gentle, collapsed_steps=None))
    s = summarize([gentle, pressed])
    assert (s["tsr"], s["dsr"], s["collapses"], s["tolerance_violations"]) == (1.0, 0.5, 1, 1)
    # Rescoring at any tolerance keeps the collapse a violation; the task success stays.
    loose = rescore_record(pressed, tau_new=1.0)
    assert loose["success"] and not loose["dsr_success"] and loose["r_max"] < 1


def test_envelope_from_sweep_records():
    recs = []
    for g, held, d in [(0.2, False, 0.001), (0.3, True, 0.002), (0.4, True, 0.004), (0.5, True, 0.006),
                       (0.6, True, 0.008), (0.7, True, 0.010)]:
        for k in range(2):
            recs.append({"closure": g, "held": held, "peak_deformation": d + 1e-4 * k, "aperture_mm": 50 - 20 * g})
    env = gripper_envelope(recs, 90)
    assert env["g_min"] == 0.3
    stable = sorted(r["peak_deformation"] for r in recs if r["held"])
    assert env["tau_o"] == pytest.approx(float(__import__("numpy").percentile(stable, 90)))
    assert env["g_max"] == 0.6  # 0.7's peaks (0.0100, 0.0101) exceed tau ~0.01
    assert env["span_mm"] == pytest.approx(20 * (0.6 - 0.3))
    with pytest.raises(ValueError, match="no closure held"):
        gripper_envelope([{"closure": 0.2, "held": False, "peak_deformation": 0.0, "aperture_mm": 40}])


def test_slip_is_measured_in_the_hand_frame():
    import numpy as np

    q_down = np.array([0.0, 1.0, 0.0, 0.0])  # hand pointing down
    tcp = np.array([[0, 0, 0.1], [0.2, 0.1, 0.3]])
    carried = tcp + [0.0, 0.0, -0.01]  # moves with the hand: no slip
    assert slip_distance(carried, tcp, np.stack([q_down, q_down])) == pytest.approx(0.0, abs=1e-12)
    slid = carried + [[0, 0, 0], [0, 0, -0.004]]
    assert slip_distance(slid, tcp, np.stack([q_down, q_down])) == pytest.approx(0.004)


def test_protocol_seeds_are_disjoint_and_ood_reuses_id_states():
    assert max(train_seed(9, 99_999), 0) < id_seed(0, 0)
    ood = episodes("object_soft", "ood", tasks=[2], per_task=3)
    ids = episodes("object_soft", "id", tasks=[2], per_task=3)
    assert len(ood) == 9 * 3 and {e["seed"] for e in ood} == {e["seed"] for e in ids}
    with pytest.raises(ValueError, match="deformable"):
        episodes("object_rigid", "ood")


def test_rigid_suites_are_scored_by_the_same_rule():
    # No special case for rigid twins: a record is DSR-successful when it succeeded with R_max <= 1,
    # whatever its suite (the twins' R_max is ~0 by physics: test_calibration).
    recs = [dict(_rec(s, r), rigid=True) for s, r in [(True, 1e-9), (True, 1.3), (False, 0.2)]]
    s = summarize([rescore_record(r, 0.01) for r in recs])
    assert [rescore_record(r, 0.01)["dsr_success"] for r in recs] == [True, False, False]
    assert s["tsr"] == pytest.approx(2 / 3) and s["dsr"] == pytest.approx(1 / 3)
    assert s["tolerance_violations"] == 1


def test_ratio_and_peak():
    d = np.array([0.01, 0.05, 0.03])
    np.testing.assert_allclose(deformation_ratio(d, 0.1), [0.1, 0.5, 0.3])
    assert r_max(deformation_ratio(d, 0.1)) == pytest.approx(0.5)
    assert r_max([]) == 0.0
    with pytest.raises(ValueError, match="positive"):
        deformation_ratio(d, 0.0)


def test_relative_difference_measures_rounding_not_other_kinds_of_change():
    from mani_skill_softvt.evaluation.runner import relative_difference

    assert relative_difference(0.5, 0.5 * (1 + 1e-15)) < 2e-15
    assert abs(relative_difference([1.0, 2.0], [1.0, 2.2]) - 0.2 / 2.2) < 1e-12
    # A count that went from 7 to 0 (collapsed steps) differs wholly, not infinitely, in either order.
    with np.errstate(all="raise"):
        assert relative_difference(7, 0) == relative_difference(0, 7) == 1.0
        assert relative_difference(0.0, 0.0) == 0.0 and relative_difference(-1.0, 1.0) == 2.0
    assert relative_difference(True, False) is None and relative_difference("a", "b") is None
    assert relative_difference([1.0], [1.0, 2.0]) is None and relative_difference(None, 1.0) is None


class _ScriptedScene:
    """Stands in for a suite env's evaluator accessors: a D_t and a collapse count per state."""

    def __init__(self, deformation, collapsed):
        import gymnasium as gym
        from types import SimpleNamespace

        self.deformation_seq, self.collapsed_seq, self.k = deformation, collapsed, 0
        outer = self

        class Env(gym.Env):
            observation_space = gym.spaces.Box(-1, 1, (1,))
            action_space = gym.spaces.Box(-1, 1, (1,))
            task = SimpleNamespace(rigid=False)
            calibration_card = SimpleNamespace(tau_o=0.01)
            target_instance = "object"

            def reset(self, seed=None, options=None):
                outer.k = 0
                return np.zeros(1), {"success": False}

            def step(self, action):
                outer.k += 1
                return np.zeros(1), 0.0, False, False, {"success": True}

            def deformation(self, name):
                return outer.deformation_seq[outer.k]

            def collapsed_tets(self):
                return outer.collapsed_seq[outer.k]

        self.env = Env()


def test_the_wrapper_fails_dsr_after_a_collapse_even_within_tolerance():
    from mani_skill_softvt.evaluation.wrapper import DSRWrapper

    scene = _ScriptedScene(deformation=[0.0, 0.002, 0.004, 0.003], collapsed=[0, 0, 2, 0])
    env = DSRWrapper(scene.env)
    env.reset()
    infos = [env.step(np.zeros(1))[-1] for _ in range(3)]
    assert [i["dsr_success"] for i in infos] == [True, False, False]  # once collapsed, for the episode
    assert [i["collapsed_tets"] for i in infos] == [0, 2, 0] and env.collapsed_steps == 1
    assert max(i["r_max"] for i in infos) == pytest.approx(0.4)  # within tolerance all along
    env.reset()
    assert env.collapsed_steps == 0 and env.step(np.zeros(1))[-1]["dsr_success"]


def test_paired_comparison_counts_matched_seeds_and_mcnemar_is_the_binomial_tail():
    from mani_skill_softvt.evaluation.metrics import mcnemar_exact_p, paired_comparison

    def rec(task, seed, success, dsr):
        return {"suite": "object_soft", "condition": "id", "task_id": task, "seed": seed,
                "success": success, "dsr_success": dsr}

    a = [rec(0, 1, True, True), rec(0, 2, True, False), rec(1, 3, False, False), rec(1, 4, True, True)]
    b = [rec(0, 1, True, False), rec(0, 2, False, False), rec(1, 3, True, True), rec(2, 9, True, True)]
    c = paired_comparison(a, b)
    assert (c["pairs"], c["both"], c["only_a"], c["only_b"], c["neither"], c["unpaired"]) == (3, 1, 1, 1, 0, 2)
    assert c["difference"] == 0.0 and c["p_value"] == 1.0
    d = paired_comparison(a, b, "dsr_success")
    assert (d["both"], d["only_a"], d["only_b"], d["neither"]) == (0, 1, 1, 1)
    # Exact tails: 0 of 5 discordant pairs to B -> 2 * (1/2)^5; 1 of 10 -> 2 * 11 / 1024.
    assert mcnemar_exact_p(5, 0) == pytest.approx(2 / 32)
    assert mcnemar_exact_p(1, 9) == pytest.approx(2 * 11 / 1024)
    assert mcnemar_exact_p(0, 0) == 1.0 and mcnemar_exact_p(3, 3) == 1.0
    with pytest.raises(ValueError, match="twice"):
        paired_comparison(a + a[:1], b)


def test_the_paired_difference_interval_covers_at_its_level():
    from mani_skill_softvt.evaluation.metrics import paired_difference_ci

    # Uncorrelated pairs (both * neither == only_a * only_b): Newcombe's interval for two
    # independent rates, each Wilson interval's half-widths added in quadrature.
    both, only_a, only_b, neither = 4, 2, 2, 1
    n = 9
    (l1, u1), (l2, u2) = wilson_interval(6, n), wilson_interval(6, n)
    lo, hi = paired_difference_ci(both, only_a, only_b, neither)
    assert lo == pytest.approx(-math.hypot(6 / n - l1, u2 - 6 / n)) and hi == pytest.approx(math.hypot(u1 - 6 / n, 6 / n - l2))
    assert paired_difference_ci(0, 0, 0, 0) == (0.0, 0.0)
    # Coverage: 2,000 draws of 100 correlated pairs (A succeeds 80 %, B 75 %, mostly on the same
    # episodes), the true difference 5 points; a 95 % interval must cover it about 95 % of the time.
    rng = np.random.default_rng(0)
    cells = np.array([0.70, 0.10, 0.05, 0.15])  # both, only A, only B, neither
    covered = 0
    for counts in rng.multinomial(100, cells, size=2000):
        lo, hi = paired_difference_ci(*map(int, counts))
        assert -1.0 <= lo <= (counts[1] - counts[2]) / 100 <= hi <= 1.0
        covered += lo <= 0.05 <= hi
    # Binomial sd of the coverage over 2,000 draws is 0.5 points: 93 % is four of them below 95 %.
    assert covered / 2000 >= 0.93


def test_records_of_earlier_versions_are_read_in_todays_format():
    """The committed records of the previous physics (campaign-data/results/old_physics) predate the
    camera size, the tactile model and the collapse count: read, they carry what those versions
    meant (native cameras, gel model 1, no collapse counted), their stored DSR outcome unchanged."""
    import json
    from pathlib import Path

    from mani_skill_softvt.evaluation.records import read_records

    path = Path(__file__).parents[1] / "campaign-data/results/old_physics/object_soft_id_vt-c-cpu.jsonl"
    if not path.exists():
        pytest.skip("needs the checkout's campaign-data/results")
    stored = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    assert not {"camera_size", "tactile_model", "collapsed_steps"} & set(stored[0])
    read = read_records(path)
    assert [r["dsr_success"] for r in read] == [s["dsr_success"] for s in stored]
    assert all(r["camera_size"] == [224, 224] and r["tactile_model"] == 1 and r["collapsed_steps"] == 0 for r in read)
    s = summarize(read)
    assert s["dsr_successes"] == sum(s_["dsr_success"] for s_ in stored) and s["collapses"] == 0
