"""The baseline file: a vehicle's clean-log statistics as versioned JSON, defined once.

The dataclasses below are the definition: the JSON a baseline is written as, the checks a file must
pass to be read, and the schema in docs/baseline.md (`schema_markdown`) all come from their fields,
types and `doc` metadata. A file of another format or version, malformed JSON or a value of the wrong
type is refused with one line naming the file and the field (`BaselineError`).
"""

from __future__ import annotations

import json
import math
import types
import typing
from dataclasses import MISSING, dataclass, field, fields, is_dataclass
from pathlib import Path
from typing import Any, TypeVar, Union

from spooflens.errors import SpooflensError

FORMAT = "spooflens-baseline"
VERSION = 1
SUFFIX = ".baseline.json"


class BaselineError(SpooflensError):
    """A baseline file that cannot be used: not one, another version, malformed, or of another vehicle."""


def doc(text: str) -> dict[str, str]:
    """A field's meaning: the schema's text."""
    return {"doc": text}


@dataclass(frozen=True)
class Quantity:
    """One quantity's distribution over the vehicle's clean logs."""

    centre: float = field(metadata=doc("median of the per-log values: the vehicle's typical level"))
    unit: str = field(metadata=doc("unit of the values ('' for counts and ratios)"))
    per_log: tuple[float | None, ...] = field(
        metadata=doc(
            "each log's value (its median, or the estimate made from it), in the order of `logs`; null where that "
            "log has none"
        )
    )
    within: float | None = field(
        default=None,
        metadata=doc(
            "typical spread inside one log: the median of the per-log robust scales (1.4826 MAD); null for a "
            "quantity with one value per log"
        ),
    )
    between: float | None = field(
        default=None,
        metadata=doc(
            "spread of the per-log values across logs (1.4826 MAD; the range / 1.128 of two logs); null with one log"
        ),
    )
    agree: bool | None = field(
        default=None,
        metadata=doc(
            "whether the logs agree on this quantity (see docs/baseline.md, 'When logs disagree'); null with one log"
        ),
    )

    @property
    def n_logs(self) -> int:
        return sum(v is not None for v in self.per_log)

    @property
    def values(self) -> list[float]:
        return [v for v in self.per_log if v is not None]


@dataclass(frozen=True)
class ClockBaseline:
    """The receiver's time against the log's clock (`time_offset_s`)."""

    clock: str = field(
        metadata=doc("the log clock the offset is against, as the reader names it (`time_offset.clock`)")
    )
    monotonic: bool = field(
        metadata=doc("whether that clock is monotonic (a boot clock) rather than a host's wall clock")
    )
    offset_scale_s: Quantity = field(
        metadata=doc("robust sigma of the offset's fix-to-fix jitter (s), as `receiver_time` measures it")
    )
    drift_ppm: Quantity | None = field(
        default=None,
        metadata=doc(
            "the offset's slope (receiver time minus log clock, parts per million): the logger crystal's rate; null "
            "when no log is long enough to tell it"
        ),
    )


@dataclass(frozen=True)
class ReceiverBaseline:
    """One receiver of the vehicle (by its receiver id in the logs)."""

    model: str | None = field(metadata=doc("receiver model found in the logs' metadata; null when no log names it"))
    firmware: tuple[str, ...] = field(default=(), metadata=doc("receiver firmware versions found in the logs"))
    indicators: dict[str, Quantity] = field(
        default_factory=dict,
        metadata=doc(
            "per fixes column (`noise_per_ms`, `jamming_indicator`, `agc`, `cn0_mean_dbhz`, `sats_used`, `hdop`, "
            "`vdop`, `h_acc_m`, `v_acc_m`, `vel_acc_mps`): its distribution"
        ),
    )
    satellite_cn0: dict[str, Quantity] = field(
        default_factory=dict,
        metadata=doc(
            "per-satellite C/N0 (dB-Hz) by elevation band (`all`, `elev_00_15`, `elev_15_30`, `elev_30_60`, "
            "`elev_60_90`): the median over the log's satellite reports"
        ),
    )
    fix_types: dict[str, Quantity] = field(
        default_factory=dict,
        metadata=doc("per fix type (spooflens.schema.FixType name): the fraction of the log's fixes of that type"),
    )
    clock: ClockBaseline | None = field(
        default=None,
        metadata=doc("the receiver's time against the log's clock; null when the logs have no `time_offset_s`"),
    )
    consistency_mode: str | None = field(
        default=None,
        metadata=doc(
            "the mode `gnss_consistency` checked the logs in (position change against reported velocity, or "
            "kinematic plausibility)"
        ),
    )
    consistency_scale: dict[str, Quantity] = field(
        default_factory=dict,
        metadata=doc(
            "per ENU axis (`east`, `north`, `up`): the robust scale of `gnss_consistency`'s residual (m, or m/s^2 "
            "for kinematic plausibility)"
        ),
    )


@dataclass(frozen=True)
class NavigationBaseline:
    """The GNSS error model and IMU noise the navigation learned from each log, and its INS coasts."""

    receiver_id: str = field(metadata=doc("the receiver the navigation used"))
    imu_id: str = field(metadata=doc("the IMU the navigation used"))
    imu_grade: str = field(metadata=doc("the IMU noise preset the learned scale multiplies"))
    parameters: dict[str, Quantity] = field(
        metadata=doc(
            "per learned parameter: `w_h`, `w_v` white position sigma (m, horizontal/vertical), `b_h`, `b_v` "
            "Gauss-Markov position sigma (m), `tau_p` its time constant (s), `wv_h`, `wv_v`, `bv_h`, `bv_v`, `tau_v` "
            "the same for velocity (m/s, s), `imu` the IMU noise scale (x the preset's variance)"
        )
    )
    coast_envelope: tuple[float, ...] = field(
        default=(),
        metadata=doc(
            "per second of coasting from 0 s: the largest ratio of GNSS's departure from an INS coast to its "
            "chi-square threshold in the clean logs (spooflens.pipeline.reconstruction's envelope; the "
            "largest over the logs)"
        ),
    )
    coast_envelope_peak: Quantity | None = field(
        default=None, metadata=doc("each log's largest envelope ratio (its agreement across logs)")
    )


@dataclass(frozen=True)
class RicePair:
    """The null model `calibrate` fits to a statistic on a log's clean part (its Rice fit)."""

    nu: Quantity = field(metadata=doc("Rice location (m; 0: Rayleigh)"))
    sigma: Quantity = field(metadata=doc("Rice scale (m)"))
    k_eff_ratio: Quantity = field(
        metadata=doc("effective independent samples per window sample (K_eff / K): the statistic's time correlation")
    )
    window_samples: int = field(metadata=doc("window length K the ratio was measured at"))


@dataclass(frozen=True)
class PairBaseline:
    """Two receivers of the vehicle (seed 003's detectors)."""

    baseline_distance: RicePair = field(metadata=doc("horizontal distance between the receivers (`baseline_collapse`)"))
    pseudorange_difference_sd: RicePair | None = field(
        default=None,
        metadata=doc(
            "spread of their pseudorange differences (`pseudorange_difference_collapse`); null without raw "
            "observations of both"
        ),
    )


@dataclass(frozen=True)
class LogEntry:
    """One clean log the baseline was learned from."""

    name: str = field(metadata=doc("file name of the log"))
    sha256: str = field(metadata=doc("SHA-256 of the log (of its files' names and bytes for a folder)"))
    duration_s: float = field(metadata=doc("length of the log (s)"))
    left_out_s: tuple[tuple[float, float], ...] = field(
        default=(), metadata=doc("stretches left out (s from the log start): its anomalies, widened by 10 s")
    )
    note: str = field(default="", metadata=doc("what was left out and why, or ''"))


@dataclass(frozen=True)
class RefusedLog:
    """A log given to `spooflens baseline` and not learned from."""

    name: str = field(metadata=doc("file name of the log"))
    reason: str = field(metadata=doc("why it was refused (e.g. a spoofing incident)"))


@dataclass(frozen=True)
class Baseline:
    """What a vehicle's (or one receiver model and antenna installation's) clean logs say is normal."""

    format: str = field(metadata=doc(f"always `{FORMAT}`"))
    version: int = field(metadata=doc(f"format version; this is version {VERSION}"))
    created_utc: str = field(metadata=doc("when the baseline was made (ISO 8601, UTC)"))
    spooflens_version: str = field(metadata=doc("the spooflens version that made it"))
    logs: tuple[LogEntry, ...] = field(metadata=doc("the clean logs it was learned from"))
    refused: tuple[RefusedLog, ...] = field(default=(), metadata=doc("logs given but not learned from, and why"))
    firmware: tuple[str, ...] = field(
        default=(), metadata=doc("autopilot, phone or logger firmware found in the logs' metadata")
    )
    imus: tuple[str, ...] = field(
        default=(), metadata=doc("IMUs found in the logs (stream id, and the reader's description where it gives one)")
    )
    receivers: dict[str, ReceiverBaseline] = field(
        default_factory=dict, metadata=doc("per receiver id (as the logs name it)")
    )
    navigation: NavigationBaseline | None = field(
        default=None, metadata=doc("the navigation's learned noise; null when the logs have no IMU")
    )
    pairs: dict[str, PairBaseline] = field(
        default_factory=dict,
        metadata=doc("per receiver pair, keyed by the first receiver's id, a vertical bar and the other's"),
    )

    # what any detector asks of a baseline -------------------------------------------------------
    def indicator(self, receiver_id: str, column: str) -> Quantity | None:
        """A receiver indicator's distribution over the clean logs (None when the baseline has none):
        `centre`, `within` (scale inside a log), `between` (spread across logs), `n_logs`, `agree`."""
        rx = self.receivers.get(receiver_id)
        return None if rx is None else rx.indicators.get(column)

    def receiver(self, receiver_id: str) -> ReceiverBaseline | None:
        return self.receivers.get(receiver_id)


T = TypeVar("T")


def _hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def _is_optional(tp: Any) -> tuple[bool, Any]:
    args = typing.get_args(tp)
    if typing.get_origin(tp) in (Union, types.UnionType) and type(None) in args:
        rest = [a for a in args if a is not type(None)]
        return True, rest[0]
    return False, tp


def to_json(x: Any) -> Any:
    """A baseline (or any part of one) as JSON-ready values (NaN and infinity as null)."""
    if is_dataclass(x) and not isinstance(x, type):
        return {f.name: to_json(getattr(x, f.name)) for f in fields(x)}
    if isinstance(x, dict):
        return {str(k): to_json(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [to_json(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def _describe(tp: Any) -> str:
    optional, inner = _is_optional(tp)
    origin, args = typing.get_origin(inner), typing.get_args(inner)
    if is_dataclass(inner):
        text = "object"
    elif origin is tuple:
        text = f"list of {_describe(args[0])}"
    elif origin is dict:
        text = f"map of {_describe(args[1])}"
    else:
        text = {float: "number", int: "integer", str: "string", bool: "boolean"}[inner]
    return text + (" or null" if optional else "")


def _parse(value: Any, tp: Any, where: str) -> Any:
    optional, inner = _is_optional(tp)
    if value is None:
        if optional or inner is float:  # a number that was NaN is written as null
            return None if optional else math.nan
        raise BaselineError(f"{where}: null where {_describe(tp)} is expected")
    origin, args = typing.get_origin(inner), typing.get_args(inner)
    if is_dataclass(inner):
        assert isinstance(inner, type)
        return from_json(value, inner, where)
    if origin is tuple:
        if not isinstance(value, list):
            raise BaselineError(f"{where}: {type(value).__name__} where a list is expected")
        return tuple(_parse(v, args[0], f"{where}[{i}]") for i, v in enumerate(value))
    if origin is dict:
        if not isinstance(value, dict):
            raise BaselineError(f"{where}: {type(value).__name__} where an object is expected")
        return {str(k): _parse(v, args[1], f"{where}.{k}") for k, v in value.items()}
    if inner is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise BaselineError(f"{where}: {value!r} is not a number")
        return float(value)
    if inner is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise BaselineError(f"{where}: {value!r} is not a whole number")
        return value
    if not isinstance(value, inner):
        raise BaselineError(f"{where}: {value!r} is not a {_describe(inner)}")
    return value


def from_json(data: Any, cls: type[T], where: str = "baseline") -> T:
    """Build `cls` from parsed JSON, checking every field against the definition."""
    if not isinstance(data, dict):
        raise BaselineError(f"{where}: {type(data).__name__} where an object is expected")
    hints = _hints(cls)
    out: dict[str, Any] = {}
    known = {f.name for f in fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(data) - known)
    if unknown:
        raise BaselineError(f"{where}: unknown field(s) {', '.join(unknown)}")
    for f in fields(cls):  # type: ignore[arg-type]
        if f.name not in data:
            if f.default is MISSING and f.default_factory is MISSING:
                raise BaselineError(f"{where}: field {f.name!r} missing")
            continue
        out[f.name] = _parse(data[f.name], hints[f.name], f"{where}.{f.name}")
    return cls(**out)


def loads(text: str, name: str) -> Baseline:
    """A baseline from its JSON text; `name` (the file) goes into every error."""
    try:
        data = json.loads(text)
    except ValueError as err:
        raise BaselineError(f"{name}: not a baseline (malformed JSON: {err})") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        found = data.get("format") if isinstance(data, dict) else None
        what = f"format {found!r}" if found else "no `format` field"
        raise BaselineError(f"{name}: not a spooflens baseline ({what}; expected {FORMAT!r})")
    if data.get("version") != VERSION:
        raise BaselineError(
            f"{name}: baseline version {data.get('version')!r}; this spooflens reads version {VERSION} "
            "(make the baseline again with `spooflens baseline`)"
        )
    try:
        return from_json(data, Baseline, name)
    except BaselineError:
        raise
    except (TypeError, ValueError) as err:
        raise BaselineError(f"{name}: {err}") from None


def load_baseline(path: Path) -> Baseline:
    """Read and check a baseline file (BaselineError with one line on any problem)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise BaselineError(f"{path}: no such baseline file") from None
    except IsADirectoryError:
        raise BaselineError(f"{path}: a folder, not a baseline file") from None
    except UnicodeDecodeError:
        raise BaselineError(f"{path}: not a baseline (not UTF-8 text)") from None
    except OSError as err:
        raise BaselineError(f"{path}: cannot be read ({err.strerror or err})") from None
    return loads(text, str(path))


def dumps(baseline: Baseline) -> str:
    return json.dumps(to_json(baseline), indent=1, allow_nan=False)


def schema_markdown() -> str:
    """The schema of a baseline file as Markdown: every field of every object, its type and meaning."""
    out: list[str] = []
    seen: list[type] = []

    def visit(cls: type) -> None:
        if cls in seen:
            return
        seen.append(cls)
        for tp in _hints(cls).values():
            for arg in (tp, *typing.get_args(tp), *(a for t in typing.get_args(tp) for a in typing.get_args(t))):
                if is_dataclass(arg) and isinstance(arg, type):
                    visit(arg)

    visit(Baseline)
    for cls in seen:
        hints = _hints(cls)
        out.append(f"#### `{cls.__name__}`\n")
        out.append((cls.__doc__ or "").strip().splitlines()[0] + "\n")
        out.append("| field | type | meaning |")
        out.append("|---|---|---|")
        for f in fields(cls):  # type: ignore[arg-type]
            required = f.default is MISSING and f.default_factory is MISSING
            tp = _describe(hints[f.name]).replace("object", _object_names(hints[f.name]))
            meaning = f.metadata.get("doc", "") + ("" if required else " (optional)")
            out.append(f"| `{f.name}` | {tp} | {meaning} |")
        out.append("")
    return "\n".join(out).strip() + "\n"


def _object_names(tp: Any) -> str:
    """The dataclass a type refers to, as a link-like name (`Quantity`), for the schema's type column."""
    stack = [tp]
    while stack:
        t = stack.pop()
        if is_dataclass(t) and isinstance(t, type):
            return f"`{t.__name__}`"
        stack.extend(typing.get_args(t))
    return "object"


if __name__ == "__main__":  # `python -m spooflens.baseline.format`: the schema section of docs/baseline.md
    print(schema_markdown(), end="")
