"""One validation result: a metric of one case, method, wall angle and resolution."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass


@dataclass
class Record:
    case: str
    method: str  # "naive" or "augmented"
    angle_deg: float
    resolution: int  # cells across the case's length scale (H/h, a/h, ...)
    metric: str
    value: float
    tolerance: float | None  # None: reported, not judged
    # "<=": pass when value <= tolerance; ">=": pass when value >= tolerance.
    sense: str = "<="
    note: str = ""

    def __post_init__(self) -> None:
        self.value = float(self.value)
        self.angle_deg = float(self.angle_deg)
        self.resolution = int(self.resolution)

    @property
    def passed(self) -> bool | None:
        if self.tolerance is None:
            return None
        if not math.isfinite(self.value):
            return False
        return bool(self.value <= self.tolerance if self.sense == "<=" else self.value >= self.tolerance)

    @classmethod
    def failed_run(cls, case: str, method: str, angle: float, resolution: int, error: Exception) -> Record:
        """The run itself failed: recorded as a metric that cannot pass, with the reason."""
        t = getattr(error, "time", float("nan"))
        return cls(case, method, angle, resolution, "run_failed_at_time_s", float(t), -1.0, note=str(error))

    def to_json(self) -> dict:
        d = asdict(self)
        d["pass"] = self.passed
        d["value"] = self.value if math.isfinite(self.value) else None
        return d
