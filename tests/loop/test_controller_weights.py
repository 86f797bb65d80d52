"""The lateral MPC's weights by name (issue 57, item 2, weights): a named tuple read by name
wherever it was read by index. Oracle: a planted configuration whose seven weights all differ,
so a name read in another's place is caught; the pinned runs (test_pins.py) hold the numbers."""

from __future__ import annotations

import numpy as np

from pipeline.loop.controller.lateral_qp import LateralQpStructure, LateralWeights

PLANTED = {"q_lateral": 1.1, "q_heading": 2.2, "q_yaw_rate": 3.3, "q_steering": 4.4,
           "r_steering_rate": 5.5, "slack_weight_linear": 6.6, "slack_weight_quadratic": 7.7}


def test_each_weight_is_read_by_its_own_name(make_config):
    cfg = make_config(["method=improved", *(f"controller.{k}={v}" for k, v in PLANTED.items())])
    weights = LateralQpStructure.of(cfg.controller, cfg.vehicle).weights
    assert isinstance(weights, LateralWeights)
    assert weights == tuple(PLANTED.values())  # a tuple still: the cache key is unchanged
    assert (weights.q_lateral, weights.q_heading, weights.q_yaw_rate, weights.q_steering,
            weights.r_steering_rate) == weights.tracking == (1.1, 2.2, 3.3, 4.4, 5.5)
    assert (weights.slack_linear, weights.slack_quadratic) == (6.6, 7.7)


def test_the_daqp_backend_reads_the_slack_weights_by_name(make_config):
    """The slack block of DAQP's QP (f = slack_linear, H = 2 slack_quadratic): the two were
    read as weights[5] and weights[6]."""
    from pipeline.loop.controller.lateral_backends import DaqpCondensedQp

    cfg = make_config(["method=improved", *(f"controller.{k}={v}" for k, v in PLANTED.items())])
    structure = LateralQpStructure.of(cfg.controller, cfg.vehicle)
    n_u = structure.control_horizon
    daqp = DaqpCondensedQp(structure, 100)
    assert np.allclose(daqp._f[n_u:], 6.6)
    assert np.allclose(np.diag(daqp._H)[n_u:], 15.4)
