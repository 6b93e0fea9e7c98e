"""Attack specifications (`KIND[:param=value,...]`) and the ground truth written beside a spoofed log."""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from enum import Enum
from pathlib import Path
from typing import Any, Literal

from spooflens.errors import SpooflensError


class AttackError(SpooflensError):
    """An attack cannot be parsed or applied to this log."""


class Kind(Enum):
    RAMP = "ramp"
    STEP = "step"
    HOVER = "hover"
    VELOCITY_PULL = "velocity_pull"
    POSITION_PULL = "position_pull"
    SINGLE_ANTENNA = "single_antenna"
    PR_DELAY = "pr_delay"
    MEACONING = "meaconing"
    BLOCKING = "blocking"
    SPOOFED_SUBSET = "spoofed_subset"
    CAPTURE = "capture"
    JAM = "jam"
    JAM_SPOOF = "jam_spoof"


# Kinds that drown the signals (interference) rather than counterfeit them, wholly or in a phase
JAMMING_KINDS = frozenset({Kind.JAM, Kind.JAM_SPOOF})
# Kinds that act on raw pseudoranges; the fixes follow through the receiver's single-point solution.
OBSERVATION_KINDS = frozenset({Kind.PR_DELAY, Kind.MEACONING, Kind.BLOCKING, Kind.SPOOFED_SUBSET})


ParamType = Literal["float", "count", "axes", "flag", "text"]
Value = float | int | str


@dataclass(frozen=True)
class Param:
    """One parameter of an attack kind: its type (how `name=value` is parsed and checked), its default
    (None: not set unless given) and what it means, with its unit."""

    name: str
    type: ParamType
    default: Value | None
    meaning: str
    unset: str = ""  # what an unset parameter without a default means (e.g. "all satellites")

    def parse(self, kind: Kind, text: str) -> Value:
        value = text.strip()
        if self.type == "text":
            if not value:
                raise AttackError(f"{kind.value}: {self.name}= needs a value")
            return value
        if self.type == "axes":
            if not value or set(value) - set("enu") or len(set(value)) != len(value):
                raise AttackError(f"{kind.value}: axes={value!r}; use a subset of e, n, u such as en")
            return value
        try:
            number = float(value)
        except ValueError:
            raise AttackError(f"{kind.value}: {self.name}={value!r} is not a number") from None
        if not math.isfinite(number):
            raise AttackError(f"{kind.value}: {self.name}={value!r} is not a finite number")
        if self.type == "float":
            return number
        if number != int(number) or number < 0 or (self.type == "flag" and number > 1):
            what = "0 or 1" if self.type == "flag" else "a whole number >= 0"
            raise AttackError(f"{kind.value}: {self.name}={value} must be {what}")
        return int(number)

    @property
    def shown(self) -> str:
        """As the docs' parameter column shows it: `name=default`, or the name and what unset means."""
        if self.default is not None:
            return (
                f"`{self.name}={self.default:g}`"
                if isinstance(self.default, float)
                else f"`{self.name}={self.default}`"
            )
        return f"`{self.name}` ({self.unset})" if self.unset else f"`{self.name}`"


@dataclass(frozen=True)
class KindSpec:
    """An attack kind: the seed paper it comes from, what it does, and its parameters."""

    seed: str
    summary: str
    params: tuple[Param, ...]

    def param(self, name: str) -> Param | None:
        return next((p for p in self.params if p.name == name), None)

    @property
    def defaults(self) -> dict[str, Value]:
        return {p.name: p.default for p in self.params if p.default is not None}


# every kind has a window (and a receiver, but single_antenna, which moves every receiver together)
_START = Param("start", "float", None, "attack start, s since the log start", "0")
_END = Param("end", "float", None, "attack end, s; the spoofer switches off there", "end of the log")
_RECEIVER = Param("receiver", "text", None, "receiver id to attack", "every receiver")
_WINDOW = (_START, _END, _RECEIVER)
WINDOW_PARAMS = frozenset(p.name for p in _WINDOW)


def _axes(default: str) -> Param:
    return Param("axes", "axes", default, "ENU axes the offset is on: a subset of e, n, u")


def _vel(default: int, meaning: str) -> Param:
    return Param("vel", "flag", default, meaning)


_SVS = Param("svs", "text", None, "satellites to attack, e.g. G05+G07 (replaces `count`)")
_SEED = Param("seed", "count", 0, "random seed of the choice of satellites")
_SYSTEMS = Param(
    "systems",
    "text",
    None,
    "act on the pseudoranges of these systems' satellites alone, e.g. G: a GPS-only spoofer (the open SDR "
    "spoofers) before a multi-constellation receiver; the fixes follow the receiver's solution of them",
    "on the fixes",
)


def _count(default: int | None) -> Param:
    return Param("count", "count", default, "satellites chosen at random among those tracked at `start`", "all")


KINDS: dict[Kind, KindSpec] = {
    Kind.RAMP: KindSpec(
        "000",
        "position drifts at `rate` m/s on each chosen axis",
        (
            Param("rate", "float", 2.0, "m/s per axis"),
            _axes("en"),
            _vel(0, "1 moves the reported velocity consistently"),
            _SYSTEMS,
            *_WINDOW,
        ),
    ),
    Kind.STEP: KindSpec(
        "000",
        "position jumps by `offset` m",
        (
            Param("offset", "float", 50.0, "m per axis"),
            _axes("en"),
            _vel(0, "no effect (a step has no velocity)"),
            _SYSTEMS,
            *_WINDOW,
        ),
    ),
    Kind.HOVER: KindSpec(
        "001",
        "reported position frozen at its value at `start`",
        (_vel(1, "1 reports zero velocity, 0 leaves it"), *_WINDOW),
    ),
    Kind.VELOCITY_PULL: KindSpec(
        "001",
        "velocity offset `dv`; position follows its integral",
        (Param("dv", "float", 0.1, "m/s per axis"), _axes("n"), _vel(1, "1 reports the pulled velocity"), *_WINDOW),
    ),
    Kind.POSITION_PULL: KindSpec(
        "001",
        "offset grows to `offset` m over `ramp` s, then holds",
        (
            Param("offset", "float", 100.0, "m per axis"),
            _axes("e"),
            Param("ramp", "float", 50.0, "s to reach the full offset"),
            _vel(0, "1 moves the reported velocity consistently"),
            *_WINDOW,
        ),
    ),
    Kind.SINGLE_ANTENNA: KindSpec(
        "003",
        "every receiver reports the first receiver's track plus a ramp: the baseline collapses",
        (
            Param("rate", "float", 1.0, "m/s per axis"),
            _axes("en"),
            _vel(0, "1 moves the reported velocity consistently"),
            _START,
            _END,
        ),
    ),
    Kind.PR_DELAY: KindSpec(
        "002, 004",
        "chosen satellites' signals arrive `delay` m late, growing at `rate` m/s (code, carrier and Doppler "
        "alike), `cn0` dB stronger (a counterfeit satellite); the same delay on every satellite moves only the clock",
        (
            Param("delay", "float", 300.0, "m (300 m is 1 us)"),
            Param("rate", "float", 0.0, "m/s growth of the delay"),
            Param("cn0", "float", 0.0, "dB added to their C/N0 (a counterfeit stronger than the real signal)"),
            _SVS,
            _count(None),
            _SEED,
            *_WINDOW,
        ),
    ),
    Kind.MEACONING: KindSpec(
        "002, 004",
        "a meaconer `east`/`north`/`up` m from where the receiver was at `start` re-broadcasts the sky `delay` "
        "m late: the fix goes to the meaconer and keeps the receiver's own noise",
        (
            Param("east", "float", 500.0, "m"),
            Param("north", "float", 0.0, "m"),
            Param("up", "float", 0.0, "m"),
            Param("delay", "float", 0.0, "m of extra replay delay"),
            *_WINDOW,
        ),
    ),
    Kind.BLOCKING: KindSpec(
        "004",
        "chosen satellites are not received (their rows removed)",
        (_SVS, _count(2), _SEED, *_WINDOW),
    ),
    Kind.SPOOFED_SUBSET: KindSpec(
        "004",
        "`keep` satellites stay authentic, every other satellite is a counterfeit delayed by `delay` m; the "
        "sidecar names the authentic set (seed 004's reference solution)",
        (
            Param(
                "keep", "count", 7, "authentic satellites, chosen at random with `seed` unless `svs` names the spoofed"
            ),
            Param("delay", "float", 300.0, "m"),
            Param("rate", "float", 0.0, "m/s growth of the delay"),
            _SVS,
            _SEED,
            *_WINDOW,
        ),
    ),
    Kind.CAPTURE: KindSpec(
        "real captures",
        "a spoofer takeover as real receivers log it: satellites lost and re-acquired over `lost` s (the fix "
        "drops out for a moment), reported accuracies and DOP inflated, noise and jamming indicator up, C/N0 "
        "down then `cn0` dB above its old level, a velocity transient of `jump` m/s; then the drag: the "
        "position pulled at `rate` m/s (`drag=ramp`), moved by `offset` m (`step`) or pulled to `offset` m "
        "over 60 s (`pull`), the reported velocity consistent with it; a spoofer `clock` s off GNSS time "
        "moves the receiver's time against the log's clock while it is captured (PX4, ArduPilot DataFlash and "
        "telemetry, GnssLogger, CSV and ROS TimeReference copies write it); when the spoofer switches off at `end`, "
        "the receiver loses and "
        "re-acquires the real sky again",
        (
            Param("drag", "text", "ramp", "how the position is dragged: ramp, step or pull"),
            Param("rate", "float", 3.0, "m/s per axis of the ramp"),
            Param("offset", "float", 200.0, "m per axis of a step or pull"),
            _axes("en"),
            Param("lost", "float", 4.0, "s of the takeover transient"),
            Param("jump", "float", 3.0, "m/s of the velocity transient"),
            Param("acc", "float", 4.0, "reported accuracy inflation at the worst of the takeover"),
            Param("cn0", "float", 4.0, "dB the spoofed signals are stronger than the real ones"),
            Param(
                "clock",
                "float",
                0.0,
                "s the spoofer's time differs from GNSS time (moves the receiver's time against the log's clock)",
            ),
            Param("seed", "count", 0, "random seed of the transient"),
            *_WINDOW,
        ),
    ),
}


_JAMMER: tuple[Param, ...] = (
    Param("cn0", "float", 15.0, "dB the C/N0 of every satellite falls at the jammer's full power"),
    Param("ramp", "float", 2.0, "s the jammer takes to reach full power (and to fade before `end`)"),
    Param("agc", "float", 0.6, "AGC at full power as a fraction of its level before (the front end turns down)"),
    Param(
        "lost",
        "count",
        None,
        "satellites lost at full power, the weakest first",
        "those the drop takes below `fix_lost_below`",
    ),
    Param(
        "fix_lost_below",
        "float",
        20.0,
        "tracking threshold, dB-Hz: a satellite below it is lost (re-acquired 3 dB above it); with fewer "
        "than 4 tracked the receiver loses its fix",
    ),
    Param("acc", "float", None, "reported accuracy inflation at full power", "10^(cn0/20), as code noise grows"),
    Param("systems", "text", None, "systems whose signals are hit, e.g. GE", "every system"),
    Param("seed", "count", 0, "random seed of the added noise"),
)
KINDS[Kind.JAM] = KindSpec(
    "interference",
    "a jammer: every satellite's C/N0 falls by `cn0` dB (rising over `ramp` s), the weakest below "
    "`fix_lost_below` dB-Hz are lost and with fewer than 4 the fix; AGC down to `agc`, noise and jamming "
    "indicator up, reported accuracies and DOP inflated and the fixes noisier by the thermal code noise, the "
    "receiver's jamming state (where it logs one) warning, critical without a fix",
    (*_JAMMER, *_WINDOW),
)
KINDS[Kind.JAM_SPOOF] = KindSpec(
    "interference, real captures",
    "jamming for `jam` s (as `jam`), then a spoofer captures the receiver as it re-acquires (as `capture`, "
    "its signals `louder` dB above the sky's and alike on every satellite); one truth file with both phases",
    (
        Param("jam", "float", 30.0, "s of jamming before the spoofer takes over"),
        *_JAMMER,
        Param("drag", "text", "ramp", "how the position is dragged: ramp, step or pull"),
        Param("rate", "float", 3.0, "m/s per axis of the ramp"),
        Param("offset", "float", 200.0, "m per axis of a step or pull"),
        _axes("en"),
        Param("reacquire", "float", 4.0, "s of the takeover transient (capture's `lost`)"),
        Param("jump", "float", 3.0, "m/s of the velocity transient"),
        Param("louder", "float", 4.0, "dB the spoofed signals are stronger than the real ones (capture's `cn0`)"),
        Param("clock", "float", 0.0, "s the spoofer's time differs from GNSS time"),
        *_WINDOW,
    ),
)


@dataclass(frozen=True)
class AttackSpec:
    kind: Kind
    params: dict[str, Any]

    @property
    def start_s(self) -> float:
        return float(self.params.get("start", 0.0))

    @property
    def end_s(self) -> float | None:
        end = self.params.get("end")
        return None if end is None else float(end)

    @property
    def axes(self) -> str:
        return str(self.params.get("axes", ""))

    def __str__(self) -> str:
        return self.kind.value + ":" + ",".join(f"{k}={v}" for k, v in self.params.items())


def parse_attack(text: str) -> AttackSpec:
    """`ramp:rate=2,axes=en,start=10` -> AttackSpec; every value parsed and checked by its kind's table."""
    name, _, rest = text.strip().partition(":")
    try:
        kind = Kind(name.strip().lower())
    except ValueError:
        raise AttackError(f"unknown attack kind {name!r}; kinds are {[k.value for k in Kind]}") from None
    spec = KINDS[kind]
    params: dict[str, Any] = dict(spec.defaults)
    for item in filter(None, (p.strip() for p in rest.split(","))):
        key, sep, value = item.partition("=")
        param = spec.param(key.strip().lower())
        if not sep or param is None:
            raise AttackError(
                f"{kind.value}: bad parameter {item!r}; parameters are {sorted(p.name for p in spec.params)}"
            )
        params[param.name] = param.parse(kind, value)
    if kind in (Kind.CAPTURE, Kind.JAM_SPOOF) and params["drag"] not in ("ramp", "step", "pull"):
        raise AttackError(f"{kind.value}: drag={params['drag']!r}; use ramp, step or pull")
    if kind in JAMMING_KINDS:
        _check_jammer(kind, params)
    if "svs" in params:
        params.pop("count", None)  # named satellites replace a random choice of them
    if params.get("start", 0.0) < 0:
        raise AttackError(f"{kind.value}: start={params['start']} is before the log start (0)")
    if "end" in params and params["end"] <= params.get("start", 0.0):
        raise AttackError(f"{kind.value}: end={params['end']} is not after start={params.get('start', 0.0)}")
    return AttackSpec(kind, params)


def _check_jammer(kind: Kind, params: dict[str, Any]) -> None:
    if params["cn0"] <= 0:
        raise AttackError(f"{kind.value}: cn0={params['cn0']} must be a positive drop in dB")
    if not 0.0 < params["agc"] <= 1.0:
        raise AttackError(f"{kind.value}: agc={params['agc']} must be a fraction in (0, 1]")
    if params["ramp"] < 0:
        raise AttackError(f"{kind.value}: ramp={params['ramp']} must be >= 0 s")
    if "acc" in params and params["acc"] < 1.0:
        raise AttackError(f"{kind.value}: acc={params['acc']} must be >= 1 (an inflation)")
    if kind == Kind.JAM_SPOOF:
        if params["jam"] <= 0:
            raise AttackError(f"jam_spoof: jam={params['jam']} must be > 0 s")
        if "end" in params and params["end"] <= params.get("start", 0.0) + params["jam"]:
            raise AttackError(f"jam_spoof: end={params['end']} leaves no spoofing after {params['jam']} s of jamming")


def attacks_markdown() -> str:
    """The table of attack kinds in docs/simulation-and-attacks.md, from KINDS (`spooflens.attacks.spec`)."""
    lines = ["| kind | seed | effect | parameters (defaults) |", "|---|---|---|---|"]
    for kind, spec in KINDS.items():
        shown = ", ".join(p.shown for p in spec.params if p.name not in WINDOW_PARAMS)
        lines.append(f"| `{kind.value}` | {spec.seed} | {spec.summary} | {shown or '-'} |")
    return "\n".join(lines)


@dataclass
class AttackTruth:
    """What was injected, for scoring detectors: written as JSON beside the spoofed log."""

    kind: str
    params: dict[str, Any]
    start_s: float
    end_s: float
    receivers: list[str]
    seed_paper: str
    source: str = ""
    t0_abs_ns: int = 0
    offsets: dict[str, list[list[float]]] = field(default_factory=dict)  # receiver -> [t_s, de, dn, du]
    satellites: list[str] = field(default_factory=list)  # raw-observation attacks: the satellites attacked
    authentic: list[str] = field(default_factory=list)  # spoofed_subset: the satellites left authentic
    # an attack of several phases (jam_spoof: jamming, then a capture): each {"kind", "start_s", "end_s", ...}
    phases: list[dict[str, Any]] = field(default_factory=list)

    def to_json(self) -> str:
        return json.dumps(asdict(self), indent=1)

    @classmethod
    def from_json(cls, text: str) -> AttackTruth:
        return cls(**json.loads(text))

    def write(self, path: Path) -> None:
        Path(path).write_text(self.to_json())

    @classmethod
    def read(cls, path: Path) -> AttackTruth:
        return cls.from_json(Path(path).read_text())


def sidecar_path(log_path: Path) -> Path:
    """Where the attack truth of a spoofed log lives: `<log>.attack.json`."""
    return Path(str(log_path).rstrip("/") + ".attack.json")
