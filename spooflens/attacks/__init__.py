"""Attack injection: spoofed copies of logs with their ground truth, so detectors can be measured.

`parse_attack("ramp:rate=2,axes=en,start=10")` -> AttackSpec; `apply_attack(table, spec)` -> (spoofed
table, AttackTruth). Fix-level kinds are in fix_attacks.py, kinds acting on raw pseudoranges in observation_attacks.py.
"""

from __future__ import annotations

from spooflens.attacks.capture import apply_capture
from spooflens.attacks.fix_attacks import apply_fix_attack
from spooflens.attacks.observation_attacks import apply_observation_attack
from spooflens.attacks.spec import (
    KINDS,
    OBSERVATION_KINDS,
    AttackError,
    AttackSpec,
    AttackTruth,
    Kind,
    parse_attack,
    sidecar_path,
)
from spooflens.epoch_table import EpochTable


def apply_attack(table: EpochTable, spec: AttackSpec) -> tuple[EpochTable, AttackTruth]:
    if spec.kind == Kind.CAPTURE:
        return apply_capture(table, spec)
    if spec.kind in OBSERVATION_KINDS:
        return apply_observation_attack(table, spec)
    return apply_fix_attack(table, spec)


__all__ = ["KINDS", "AttackError", "AttackSpec", "AttackTruth", "Kind", "apply_attack", "parse_attack", "sidecar_path"]
