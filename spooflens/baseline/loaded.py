"""A baseline as an analysis uses it: the file's content, its name and SHA-256 (for the outputs'
provenance), and what differs between the log and the logs it was learned from.

`check` refuses a baseline whose receivers are not the log's (other receiver ids, or another model:
BaselineError, exit 2) and warns where firmware or IMUs differ or a model cannot be checked.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, replace
from pathlib import Path

from spooflens.baseline.format import Baseline, BaselineError, load_baseline
from spooflens.baseline.identity import identify, same_model
from spooflens.epoch_table import EpochTable


@dataclass(frozen=True)
class LoadedBaseline:
    content: Baseline
    file: str  # the file's name
    sha256: str
    warnings: tuple[str, ...] = ()  # how the log differs from the baseline's logs


def load(path: Path) -> LoadedBaseline:
    """Read and check a baseline file (BaselineError, one line, on any problem)."""
    baseline = load_baseline(path)
    return LoadedBaseline(baseline, Path(path).name, hashlib.sha256(Path(path).read_bytes()).hexdigest())


def check(loaded: LoadedBaseline, table: EpochTable) -> LoadedBaseline:
    """The baseline with the warnings for this log; BaselineError when it is another vehicle's receiver."""
    b, name = loaded.content, loaded.file
    ident = identify(table)
    common = [rid for rid in ident.receivers if rid in b.receivers]
    if ident.receivers and not common:
        raise BaselineError(
            f"{name}: a baseline of receiver(s) {', '.join(b.receivers) or 'none'}, {table.source.name} has "
            f"{', '.join(ident.receivers)}: none in common (a baseline of another vehicle or log format?)"
        )
    warnings = []
    for rid in common:
        mine, theirs = ident.receivers[rid], b.receivers[rid].model
        if mine and theirs and not same_model(mine, theirs):
            raise BaselineError(
                f"{name}: receiver {rid} of the baseline is a {theirs}, of {table.source.name} a {mine}: "
                "a baseline of another receiver model is no yardstick"
            )
        if bool(mine) != bool(theirs):
            which = (
                f"the log names none, the baseline {theirs}" if theirs else f"the log names {mine}, the baseline none"
            )
            warnings.append(f"receiver {rid}: its model cannot be checked ({which})")
    if (
        ident.receiver_firmware
        and b.receivers
        and not set(ident.receiver_firmware) & {f for r in b.receivers.values() for f in r.firmware}
    ):
        known = sorted({f for r in b.receivers.values() for f in r.firmware}) or ["none named"]
        warnings.append(
            f"receiver firmware {', '.join(ident.receiver_firmware)}; the baseline's logs: {', '.join(known)}"
        )
    if ident.firmware and not set(ident.firmware) & set(b.firmware):
        warnings.append(
            f"firmware {', '.join(ident.firmware)}; the baseline's logs: {', '.join(b.firmware) or 'none named'}"
        )
    new_imus = [i for i in ident.imus if i not in b.imus]
    if new_imus:
        warnings.append(f"IMU {', '.join(new_imus)} not in the baseline's logs ({', '.join(b.imus) or 'none'})")
    missing = [rid for rid in ident.receivers if rid not in b.receivers]
    if missing:
        warnings.append(f"receiver(s) {', '.join(missing)} not in the baseline: judged against the log alone")
    return replace(loaded, warnings=tuple(warnings))
