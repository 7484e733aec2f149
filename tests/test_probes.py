"""The touch probes' maths (studies/touch_probes.py): labels, ridge regression, scores."""

import numpy as np

from softvt_campaign.studies.touch_probes import (
    RidgeSolver,
    balanced_accuracy,
    r2,
    ridge_fit,
    roc_auc,
    slip_labels,
)


def test_slip_is_relative_motion_in_contact_above_the_threshold():
    # The TCP lifts at 1 cm/s; the object follows exactly, then lags by 2 mm/s for one step, and
    # finally moves away while the pads no longer press.
    t = np.arange(5)[:, None] * 0.05
    tcp = np.hstack([np.zeros((5, 2)), 0.01 * t])
    obj = tcp.copy()
    obj[2:, 2] -= 0.002 * 0.05  # lags 0.1 mm between states 1 and 2: 2 mm/s
    obj[4, 0] += 0.01  # a jump of 1 cm between states 3 and 4
    contact = np.array([True, True, True, False])
    assert slip_labels(obj, tcp, contact).tolist() == [False, True, False, False]
    assert slip_labels(obj, tcp, np.ones(4, bool)).tolist() == [False, True, False, True]


def test_ridge_recovers_a_linear_map_and_shrinks_with_the_penalty():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(400, 5))
    w_true = np.array([1.0, -2.0, 0.5, 0.0, 3.0])
    y = x @ w_true + 4.0
    w, b = ridge_fit(x, y, 1e-9)
    np.testing.assert_allclose(w, w_true, atol=1e-6)
    assert abs(b - 4.0) < 1e-6 and r2(y, x @ w + b) > 1 - 1e-9
    w_big, _ = ridge_fit(x, y, 1e3)
    assert np.linalg.norm(w_big) < 0.01 * np.linalg.norm(w_true)
    assert abs(r2(y, np.full_like(y, y.mean()))) < 1e-12  # the mean scores 0


def test_ridge_read_in_blocks_equals_the_closed_form_on_the_whole_matrix(monkeypatch):
    # The solver reads a float32 input in float64 blocks; the blocks must add up to the normal
    # equations of the whole, centred matrix (to float64 rounding, not float32's).
    rng = np.random.default_rng(1)
    x = (rng.normal(size=(300, 6)) + 5.0).astype(np.float32)  # off-centre: the centring matters
    y = rng.normal(size=300)
    monkeypatch.setattr(RidgeSolver, "BLOCK", 64)  # 5 blocks, the last one short
    w, b = RidgeSolver(x).fit(y, 0.1)
    xc = x.astype(np.float64) - x.astype(np.float64).mean(0)
    w_ref = np.linalg.solve(xc.T @ xc + 0.1 * 300 * np.eye(6), xc.T @ (y - y.mean()))
    np.testing.assert_allclose(w, w_ref, rtol=1e-10, atol=1e-12)
    assert abs(b - (y.mean() - x.astype(np.float64).mean(0) @ w_ref)) < 1e-10


def test_auc_and_balanced_accuracy_match_their_definitions():
    labels = np.array([True, True, False, False, False])
    assert roc_auc(labels, np.array([0.9, 0.8, 0.1, 0.2, 0.3])) == 1.0
    assert roc_auc(labels, np.array([0.1, 0.2, 0.9, 0.8, 0.7])) == 0.0
    # One positive above all three negatives, one below two of them: (3 + 1) / 6.
    assert abs(roc_auc(labels, np.array([0.9, 0.2, 0.1, 0.5, 0.3])) - 4 / 6) < 1e-12
    assert roc_auc(labels, np.zeros(5)) == 0.5  # ties count half
    assert balanced_accuracy(labels, np.array([True, False, False, False, True])) == 0.5 * (1 / 2 + 2 / 3)
    assert np.isnan(balanced_accuracy(np.ones(3, bool), np.ones(3, bool)))
