"""What a train sees that the operator must see too: its corrections going stale (issue 19: a train's
correction age rose while no alarm was raised). One alarm per train and episode, cleared when fresh again."""

from __future__ import annotations

from augnet.system.rbc_link import MAX_CORRECTION_AGE_S  # one limit for the RBC's watchdog and the trains'

KIND = "train-correction-stale"


def train_subject(train_id: str) -> str:
    return f"train {train_id}"


class TrainCorrectionWatch:
    """Per train: the age of the newest correction epoch it received (now minus that epoch's time) against
    `limit_s`. A train that never received one is not judged (it is still starting)."""

    def __init__(self, limit_s: float = MAX_CORRECTION_AGE_S) -> None:
        self.limit_s = limit_s
        self._stale: set[str] = set()

    def check(self, train_id: str, newest_correction_gpst: float | None,
              now_gpst: float) -> list[tuple[str, str, str, str, bool]]:
        """Alarm-store events (kind, subject, severity, message, cleared) for this train now: a raise when
        its corrections went stale, a clear when they are fresh again, else none."""
        if newest_correction_gpst is None:
            return []
        age = now_gpst - newest_correction_gpst
        if age > self.limit_s and train_id not in self._stale:
            self._stale.add(train_id)
            return [(KIND, train_subject(train_id), "warning",
                     f"train {train_id}: corrections {age:.1f} s old (limit {self.limit_s:g} s)", False)]
        if age <= self.limit_s and train_id in self._stale:
            self._stale.discard(train_id)
            return [(KIND, train_subject(train_id), "warning", f"train {train_id}: corrections fresh", True)]
        return []
