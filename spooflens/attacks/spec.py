"""Attack specifications (`KIND[:param=value,...]`) and the ground truth written beside a spoofed log."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from enum import Enum
from pathlib import Path
from typing import Any

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


# Kinds that act on raw pseudoranges; the fixes follow through the receiver's single-point solution.
OBSERVATION_KINDS = frozenset({Kind.PR_DELAY, Kind.MEACONING, Kind.BLOCKING, Kind.SPOOFED_SUBSET})


@dataclass(frozen=True)
class KindInfo:
    seed: str
    summary: str
    params: dict[str, str]  # name -> meaning (with unit and default)


_SATELLITES = {
    "svs": "satellites to attack, e.g. G05+G07 (default: `count` of them, or all)",
    "count": "how many satellites, chosen at random among those tracked at `start` (default: all)",
    "seed": "random seed of that choice (default 0)",
}
_WINDOW = {
    "start": "attack start, s since the log start (default 0)",
    "end": "attack end, s (default: end of log); the spoofer switches off there",
    "receiver": "receiver id to attack (default: every receiver)",
}
KINDS: dict[Kind, KindInfo] = {
    Kind.RAMP: KindInfo(
        "000",
        "position drifts at `rate` m/s on each chosen axis; velocity untouched",
        {
            "rate": "m/s per axis (default 2)",
            "axes": "subset of e, n, u (default en)",
            "vel": "1 to move the reported velocity consistently (default 0)",
            **_WINDOW,
        },
    ),
    Kind.STEP: KindInfo(
        "000",
        "position jumps by `offset` m on each chosen axis",
        {"offset": "m per axis (default 50)", "axes": "default en", "vel": "ignored", **_WINDOW},
    ),
    Kind.HOVER: KindInfo(
        "001",
        "reported position frozen at its value at `start` (and velocity zero)",
        {"vel": "1 (default) reports zero velocity, 0 leaves it", **_WINDOW},
    ),
    Kind.VELOCITY_PULL: KindInfo(
        "001",
        "velocity offset `dv` m/s on the chosen axes; position follows its integral",
        {
            "dv": "m/s per axis (default 0.1)",
            "axes": "default n",
            "vel": "1 (default) reports the pulled velocity",
            **_WINDOW,
        },
    ),
    Kind.POSITION_PULL: KindInfo(
        "001",
        "position offset grows linearly to `offset` m over `ramp` s, then holds",
        {
            "offset": "m per axis (default 100)",
            "axes": "default e",
            "ramp": "s to reach the full offset (default 50)",
            "vel": "default 0",
            **_WINDOW,
        },
    ),
    Kind.SINGLE_ANTENNA: KindInfo(
        "003",
        "one spoofer antenna: every receiver reports the same false position "
        "(the first receiver's track plus a ramp of `rate` m/s), so the "
        "baseline between receivers collapses",
        {
            "rate": "m/s per axis (default 1)",
            "axes": "default en",
            "vel": "default 0",
            "start": _WINDOW["start"],
            "end": _WINDOW["end"],
        },
    ),
    Kind.PR_DELAY: KindInfo(
        "002, 004",
        "every chosen satellite's signal arrives `delay` m late (growing at `rate` m/s): pseudorange, "
        "carrier phase and Doppler move together, as for a replayed signal; the same delay on every "
        "satellite moves only the receiver clock (seed 004's bias injection)",
        {
            "delay": "m (default 300, i.e. 1 us)",
            "rate": "m/s growth of the delay (default 0)",
            **_SATELLITES,
            **_WINDOW,
        },
    ),
    Kind.MEACONING: KindInfo(
        "002, 004",
        "a meaconer antenna `east`/`north`/`up` m from where the receiver was at `start` re-broadcasts the "
        "whole sky `delay` m late: every pseudorange becomes the meaconer's, so the fix moves there",
        {
            "east": "m (default 500)",
            "north": "m (default 0)",
            "up": "m (default 0)",
            "delay": "m of extra replay delay (default 0)",
            **_WINDOW,
        },
    ),
    Kind.BLOCKING: KindInfo(
        "004",
        "the chosen satellites are not received at all (rows removed); the fix moves with the geometry",
        {**_SATELLITES, **_WINDOW},
    ),
    Kind.SPOOFED_SUBSET: KindInfo(
        "004",
        "`keep` satellites stay authentic; every other satellite is replaced by a counterfeit delayed by "
        "`delay` m (growing at `rate` m/s). On a log this is bias injection on the complement; the truth "
        "sidecar names the authentic set, whose solution is seed 004's reference position",
        {
            "keep": "authentic satellites (default 7), chosen at random with `seed` unless `svs` names the spoofed",
            "delay": "m (default 300)",
            "rate": "m/s (default 0)",
            "svs": _SATELLITES["svs"],
            "seed": _SATELLITES["seed"],
            **_WINDOW,
        },
    ),
    Kind.CAPTURE: KindInfo(
        "real captures",
        "a spoofer takeover as real receivers log it: satellites lost and re-acquired over `lost` s (the fix "
        "drops out for a moment), reported accuracies and DOP inflated, noise and jamming indicator up, C/N0 "
        "down then `cn0` dB above its old level, a velocity transient of `jump` m/s; then the drag: the "
        "position pulled at `rate` m/s (`drag=ramp`), moved by `offset` m (`step`) or pulled to `offset` m "
        "over 60 s (`pull`), the reported velocity consistent with it; when the spoofer switches off at "
        "`end`, the receiver loses and re-acquires the real sky again",
        {
            "drag": "ramp, step or pull (default ramp)",
            "rate": "m/s per axis of the ramp (default 3)",
            "offset": "m per axis of a step or pull (default 200)",
            "axes": "default en",
            "lost": "s of the takeover transient (default 4)",
            "jump": "m/s of the velocity transient (default 3)",
            "acc": "reported accuracy inflation at the worst of the takeover (default 4)",
            "cn0": "dB the spoofed signals are stronger than the real ones (default 4)",
            "seed": "random seed of the transient (default 0)",
            **_WINDOW,
        },
    ),
}
_DEFAULTS: dict[Kind, dict[str, Any]] = {
    Kind.RAMP: {"rate": 2.0, "axes": "en", "vel": 0},
    Kind.STEP: {"offset": 50.0, "axes": "en", "vel": 0},
    Kind.HOVER: {"vel": 1},
    Kind.VELOCITY_PULL: {"dv": 0.1, "axes": "n", "vel": 1},
    Kind.POSITION_PULL: {"offset": 100.0, "axes": "e", "ramp": 50.0, "vel": 0},
    Kind.SINGLE_ANTENNA: {"rate": 1.0, "axes": "en", "vel": 0},
    Kind.PR_DELAY: {"delay": 300.0, "rate": 0.0, "seed": 0},
    Kind.MEACONING: {"east": 500.0, "north": 0.0, "up": 0.0, "delay": 0.0},
    Kind.BLOCKING: {"count": 2, "seed": 0},
    Kind.SPOOFED_SUBSET: {"keep": 7, "delay": 300.0, "rate": 0.0, "seed": 0},
    Kind.CAPTURE: {
        "drag": "ramp",
        "rate": 3.0,
        "offset": 200.0,
        "axes": "en",
        "lost": 4.0,
        "jump": 3.0,
        "acc": 4.0,
        "cn0": 4.0,
        "seed": 0,
    },
}


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
    """`ramp:rate=2,axes=en,start=10` -> AttackSpec, with errors listing kinds and parameters."""
    name, _, rest = text.strip().partition(":")
    try:
        kind = Kind(name.strip().lower())
    except ValueError:
        raise AttackError(f"unknown attack kind {name!r}; kinds are {[k.value for k in Kind]}") from None
    params: dict[str, Any] = dict(_DEFAULTS[kind])
    for item in filter(None, (p.strip() for p in rest.split(","))):
        key, sep, value = item.partition("=")
        key = key.strip().lower()
        if not sep or key not in KINDS[kind].params:
            raise AttackError(f"{kind.value}: bad parameter {item!r}; parameters are {sorted(KINDS[kind].params)}")
        if key in ("axes", "receiver", "svs", "drag"):
            params[key] = value.strip()
        else:
            try:
                params[key] = float(value)
            except ValueError:
                raise AttackError(f"{kind.value}: {key}={value!r} is not a number") from None
    if kind == Kind.CAPTURE and params["drag"] not in ("ramp", "step", "pull"):
        raise AttackError(f"capture: drag={params['drag']!r}; use ramp, step or pull")
    axes = str(params.get("axes", ""))
    if axes and (set(axes) - set("enu") or len(set(axes)) != len(axes)):
        raise AttackError(f"{kind.value}: axes={axes!r}; use a subset of e, n, u such as en")
    for key in ("count", "keep", "seed"):
        if key in params and (params[key] != int(params[key]) or params[key] < 0):
            raise AttackError(f"{kind.value}: {key}={params[key]:g} must be a whole number >= 0")
    if "svs" in params:
        params.pop("count", None)  # named satellites replace a random choice of them
    if "end" in params and params["end"] <= params.get("start", 0.0):
        raise AttackError(f"{kind.value}: end={params['end']} is not after start={params.get('start', 0.0)}")
    return AttackSpec(kind, params)


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
