"""`augmpm validate`: both boundary methods against answers nobody on the team wrote.

Each case module's `run` returns `Record`s; `augmpm.validation.suite.run_validation` runs them all
and writes `results.json`, `report.md` and one PNG per case.
"""

from augmpm.validation.records import Record

__all__ = ["Record"]
