"""Synthetic inputs several test folders share (a trajectory table with the simulator's
columns, a scripted out-and-back detour, the lateral MPC's inputs). A plain module beside the
root ``conftest.py``, which puts this folder on ``sys.path``: imported as ``builders`` from any
folder, never as ``tests.<file>`` (that import depended on how pytest was started)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from pipeline.loop.controller import MpcInputs


def synthetic(t, x, y, psi=None, r=None, delta=None, v=3.0, obstacle=None, appear=0.0):
    """A trajectory table with the simulator's columns."""
    n = len(t)
    psi = np.zeros(n) if psi is None else psi
    frame = pd.DataFrame({"time_s": t, "X_m": x, "Y_m": y, "psi_rad": psi,
                          "vx_mps": np.full(n, v), "vy_mps": np.zeros(n),
                          "r_rad_s": np.zeros(n) if r is None else r,
                          "delta_rad": np.zeros(n) if delta is None else delta})
    if obstacle is not None:
        frame["obs0_x_m"], frame["obs0_y_m"] = obstacle[0], obstacle[1]
        frame["obs0_radius_m"] = obstacle[2]
        frame["obs0_visible"] = t >= appear - 1e-9
    return frame


def out_and_back(overshoot: float, swings: int = 0) -> pd.DataFrame:
    """A detour to +1 m around an obstacle at x = 12, back to the line by x = 21, then an
    overshoot of ``overshoot`` m and ``swings`` further damped reversals."""
    t = np.round(np.arange(0.0, 14.0 + 1e-9, 0.1), 10)
    x = 3.0 * t
    y = np.clip(np.minimum((x - 6.0) / 3.0, (21.0 - x) / 6.0), 0.0, 1.0)
    tail = x > 21.0
    phase = (x[tail] - 21.0) / 3.0 * np.pi
    decay = np.exp(-(x[tail] - 21.0) / (3.0 * (swings + 1)))
    y[tail] = -overshoot * np.sin(np.minimum(phase, np.pi * (swings + 1))) * decay
    psi = np.arctan(np.gradient(y, x))
    return synthetic(t, x, y, psi=psi, r=np.gradient(psi, t), obstacle=(12.0, 0.0, 0.3),
                     appear=1.0)


def make_inputs(model, cfg, x0, y_ref, psi_ref, G=None, h=None):
    N, M = cfg.horizon, cfg.max_obstacles
    return MpcInputs(x0, model, y_ref, psi_ref, np.zeros((N, M)) if G is None else G,
                     np.zeros((N, M)) if h is None else h, np.zeros(N))


def stored_trials(store) -> list[tuple[str, object]]:
    """Every trial in a tune's trial store (its journal) as a fresh Optuna reads it with its
    own file backend: ``(study name, FrozenTrial)`` in the order the studies were made."""
    from optuna.storages import JournalStorage
    from optuna.storages.journal import JournalFileBackend

    storage = JournalStorage(JournalFileBackend(str(store)))
    return [(study.study_name, trial) for study in storage.get_all_studies()
            for trial in storage.get_all_trials(study._study_id)]
