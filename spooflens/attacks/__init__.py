"""Attack injection: spoofed copies of logs with their ground truth, so detectors can be measured.

`parse_attack("ramp:rate=2,axes=en,start=10")` -> AttackSpec; `apply_attack(table, spec)` -> (spoofed
table, AttackTruth). Fix-level kinds are in fix_attacks.py, kinds acting on raw pseudoranges in observation_attacks.py.
"""

from __future__ import annotations

from spooflens.attacks.capture import apply_capture
from spooflens.attacks.fix_attacks import apply_fix_attack
from spooflens.attacks.jamming import apply_jam, apply_jam_spoof
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
    """The attack applied to the log's data; a window starting after the data ends is refused.

    A fix-level kind on a log whose receivers logged only pseudoranges (RINEX, a CSV of observations)
    acts on the pseudoranges: the fixes `analyze` solves from them then follow the attack.
    A ramp or step given `systems` acts on those systems' pseudoranges alone (a GPS-only spoofer before
    a multi-constellation receiver).
    """
    if spec.kind == Kind.JAM:
        _check_start(table, spec, "fixes" if len(table.fixes) else "observations")
        return apply_jam(table, spec)
    if spec.kind == Kind.JAM_SPOOF:
        if not len(table.fixes):
            raise AttackError(f"{table.source}: jam_spoof needs the receivers' fixes; this log has only pseudoranges")
        _check_start(table, spec, "fixes")
        return apply_jam_spoof(table, spec)
    if "systems" in spec.params and not len(table.observations):
        raise AttackError(f"{table.source}: systems= acts on raw pseudoranges and this log has none")
    on_observations = (
        spec.kind in OBSERVATION_KINDS
        or "systems" in spec.params
        or (not len(table.fixes) and len(table.observations) > 0)
    )
    attacked = table.observations if on_observations else table.fixes
    if len(attacked):
        last = float(attacked["t_s"].max())
        if spec.start_s > last:
            raise AttackError(
                f"{table.source}: start={spec.start_s:g} s is after the end of the log's "
                f"{'observations' if on_observations else 'fixes'} ({last:.1f} s); nothing to attack"
            )
    if on_observations:
        if spec.kind in (Kind.SINGLE_ANTENNA, Kind.CAPTURE):
            raise AttackError(
                f"{table.source}: {spec.kind.value} needs the receivers' fixes; this log has only pseudoranges"
                + (
                    " (spooflens.attacks.single_antenna_raw makes the raw-observation equivalent)"
                    if spec.kind == Kind.SINGLE_ANTENNA
                    else ""
                )
            )
        return apply_observation_attack(table, spec)
    if spec.kind == Kind.CAPTURE:
        return apply_capture(table, spec)
    return apply_fix_attack(table, spec)


def _check_start(table: EpochTable, spec: AttackSpec, frame: str) -> None:
    rows = getattr(table, frame)
    if len(rows) and spec.start_s > float(rows["t_s"].max()):
        raise AttackError(
            f"{table.source}: start={spec.start_s:g} s is after the end of the log's {frame} "
            f"({float(rows['t_s'].max()):.1f} s); nothing to attack"
        )


__all__ = ["KINDS", "AttackError", "AttackSpec", "AttackTruth", "Kind", "apply_attack", "parse_attack", "sidecar_path"]
