"""What an analysis runs on: the log's table, the user's options, and the work its detectors share
(computed once, cached). Its own module so that the checks and helpers the registry calls can name it
without importing the registry."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from spooflens.baseline.loaded import LoadedBaseline
from spooflens.detectors.base import DetectorResult
from spooflens.epoch_table import EpochTable


@dataclass
class AnalyzeOptions:
    """User choices that analyses read (CLI flags map here)."""

    imu_id: str | None = None
    receiver_id: str | None = None
    imu_grade: str | None = None
    extra: dict[str, object] = field(default_factory=dict)
    # a vehicle's clean-log statistics (`spooflens baseline`, `--baseline`): detectors take yardsticks from it
    baseline: LoadedBaseline | None = None


@dataclass
class AnalysisContext:
    """What an analysis runs on; shared work is computed once and cached."""

    table: EpochTable
    options: AnalyzeOptions
    cache: dict[str, Any] = field(default_factory=dict)
    # of the analyses that ran before (one that finishes `Later` joins them when every analysis has run)
    results: list[DetectorResult] = field(default_factory=list)
    # the stretch of the log this context holds, when it is one the navigation ran on between the IMU's
    # gaps (`navigation_parts`); None: the whole log
    span_s: tuple[float, float] | None = None

    def cached(self, key: str, make: Callable[[], Any]) -> Any:
        if key not in self.cache:
            self.cache[key] = make()
        return self.cache[key]
