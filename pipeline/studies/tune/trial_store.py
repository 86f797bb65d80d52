"""The tune's trial store: Optuna's cached storage over the SQLite file, writing a trial in a
few commits (imported when a tune opens its store: Optuna is imported here)."""

from __future__ import annotations

from optuna.storages._cached_storage import _CachedStorage


class BatchedTrialStorage(_CachedStorage):
    """Optuna's cached storage over ``backend`` (an ``RDBStorage``), writing a running
    trial's parameters and attributes in one commit when asked (:meth:`flush`) or when the
    trial finishes, instead of one commit per parameter and attribute (Optuna 2.10's
    ``_CachedStorage``, pinned, commits each: a dozen per trial, a quarter of the tune
    parent's CPU with five-member rungs). Only this process writes a running trial (the
    tune's parent owns every study; a second tune on the folder is refused), and it reads the
    trial from the cache, so the trials it asks and tells are the same; a running trial in
    the file holds its parameters once its batch is asked (what an interrupted tune's resume
    needs), its attributes once it is told. The file is read for a study's trials only while
    it has some this process neither owns nor saw finish."""

    def __init__(self, backend) -> None:
        super().__init__(backend)
        #: the studies whose trials this process has read from the file
        self.read_studies: set[int] = set()

    def _flush_trial(self, trial_id: int) -> bool:
        # called with the lock held after each update: only a finished trial is written
        mapped = self._trial_id_to_study_id_and_number.get(trial_id)
        if mapped is not None:
            updates = self._studies[mapped[0]].updates.get(mapped[1])
            if updates is not None and (updates.state is None
                                        or not updates.state.is_finished()):
                return True
        return super()._flush_trial(trial_id)

    def read_trials_from_remote_storage(self, study_id: int) -> None:
        # Optuna reads the file for every trial this process neither owns nor saw finish, on
        # every read of the study (a query excluding every known trial id: it grows with the
        # study); with one writer that is only a trial of an earlier process still open, or
        # one enqueued and not yet asked. (Optuna makes a study's cache entry before reading
        # its trials: the studies read are counted here.)
        with self._lock:
            study = self._studies.get(study_id)
            if study is not None and study_id in self.read_studies and all(
                    t._trial_id in study.owned_or_finished_trial_ids
                    for t in study.trials.values()):
                return
        super().read_trials_from_remote_storage(study_id)
        with self._lock:
            self.read_studies.add(study_id)

    def flush(self, trial_id: int) -> bool:
        """Write ``trial_id``'s pending updates now (one commit)."""
        with self._lock:
            return super()._flush_trial(trial_id)
