"""Natural explanations of an incident's evidence: what, besides a spoofer, makes these alarms.

Each signature is a stated test on the log's own data at an alarm's time (`spooflens.pipeline.indicators`:
the receiver's indicators against their level just before, its sky, its time, the other receivers) that
names a natural cause and the alarm it accounts for:

- degradation (multipath, NLOS, obstruction, foliage): the C/N0 falls and one more of DOP or reported
  accuracy up, satellites lost, the fix lost, while the fix moves no more than a reflection moves it; or,
  the C/N0 steady, satellites lost and the DOP or reported accuracy up with them (satellites blocked whole
  leave those still tracked as strong as before);
- interference: the receiver's jamming state, jamming indicator, noise or AGC moved (the interference
  detector's class, when it ran);
- a jammed receiver's noisier fixes against the INS: under interference, GNSS departed from the INS
  (the navigation filter's innovations) no more than the receiver's error before, grown by the thermal
  noise its C/N0 loss implies, allows, without a steady drift; an alarm is accounted for up to the
  first epoch that departs further (a spoofer's takeover inside one alarm), not beyond;
- convergence: the receiver's first minutes after its first fix (or after the fix was lost for 10 s),
  its DOP, satellites, fix type or accuracy still settling;
- mode switch: the fix type changed (SBAS, DGNSS, RTK float/fixed) where the fix moved, by metres;
- skipped fix: the fix moved one fix period's travel more (or less) than its velocity over one interval,
  alone: an output or gateway cycle not locked to the fixes dropped (or repeated) one;
- time faults: the receiver's time moved against the log's clock by whole GPS week epochs (1024 weeks:
  a week rollover) or by a whole number of leap seconds;
- one satellite's range a reflection's length off (NLOS), its C/N0 not raised, or two at once each within it;
- a satellite the receiver never used in its fix from the log's start cannot have moved it;
- a known station's antenna moved and put back: its satellites' rates agree on one motion of the receiver
  that takes it no more than a hand or a knock does (5 m) from the known position and back within 30 s
  (a rover standing still while its antenna is handled, its header position taken for a station);
- an inertial shock: the vehicle's own IMU read a tumble or an impact (angular rate or specific force far
  beyond flight, at the gyro's or accelerometer's full scale) just before an inertial alarm began; an
  INS integrating through it, the autopilot's or spooflens', has lost its attitude and departs from GNSS
  until it re-converges (a crash, a hard landing).

Before any of the receiver's own indicators is read as a natural cause, the marks a spoofer leaves and
nature does not are looked for (`spoofer_marks`): C/N0 raised above its level or above what the sky
gives, the satellites at one C/N0 at their usual level, the receiver's own spoofing flag, its time moved
against the log's clock. Where one is found no natural explanation of the GNSS-internal alarms holds.
No sky signature accounts for an inertial, heading or fleet alarm: their references do not see the
sky. Two causes reach an inertial alarm: the inertial shock, and only for one that began after the shock
(a spoofer cannot move an IMU, and an attack under way before the crash keeps its evidence); and a
jammed receiver's noise, bounded by what its C/N0 loss implies. A cause may account for an alarm from its
start up to a time (`Reading.until_s`): what follows counts. The tests' numbers and the real logs that
show each are in docs/verdict.md.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from spooflens.detectors.base import Alarm, DetectorResult
from spooflens.detectors.gnss_consistency import NAME as GNSS_CONSISTENCY
from spooflens.detectors.gnss_consistency import ConsistencyOptions
from spooflens.detectors.range_rate import NAME as RANGE_RATE
from spooflens.detectors.range_rate import TTEST as RANGE_RATE_TTEST
from spooflens.detectors.receiver_evidence import NAME as RECEIVER_EVIDENCE
from spooflens.epoch_table import EpochTable
from spooflens.geodesy import small_move_en_m
from spooflens.navigation.product import NAVIGATION
from spooflens.pipeline.evidence import Evidence, Span
from spooflens.pipeline.indicators import BoolArray, FloatArray, Receiver, Window, running_median
from spooflens.pipeline.verdict import Explanation, Incident, Kind, SpooferMark
from spooflens.schema import FixType

WEEK_S = 604_800.0
ROLLOVER_S = 1024 * WEEK_S
JAMMED = "jammed receiver's noise"
HELD_FIX = "held fix"
# a coast starts this long before the onset of the incident it checks (`CoastingOptions.margin_s`, and more)
DEPARTURE_LEAD_S = 2.0
# the alarms a receiver's indicators can account for: the fix against itself, the receiver's indicators
INDICATOR_DETECTORS = frozenset({GNSS_CONSISTENCY, RECEIVER_EVIDENCE})
FIX_NAMES = {
    FixType.FIX_2D: "2D",
    FixType.FIX_3D: "3D",
    FixType.SBAS: "SBAS",
    FixType.DGNSS: "DGNSS",
    FixType.RTK_FLOAT: "RTK float",
    FixType.RTK_FIXED: "RTK fixed",
}


@dataclass(frozen=True)
class ExplanationOptions:
    window_before_s: float = 10.0  # a cause precedes the alarm it makes: an alarm's window opens this long before
    window_after_s: float = 2.0
    # degradation: a fall of the C/N0, and one more sign
    min_cn0_drop_db: float = 3.0
    # or a sky weak all along, before the alarm and during it (indoors, under a canopy, a poor antenna: an
    # open sky gives 30-50 dB-Hz to a small antenna, a phone's 25-45): at the tracking floor a receiver
    # loses satellites and its fix without any further fall; no spoofer is weaker than the sky it overpowers
    weak_sky_dbhz: float = 25.0
    dop_ratio: float = 1.5
    dop_min_rise: float = 0.3
    accuracy_ratio: float = 1.5
    accuracy_min_rise_m: float = 1.0
    min_satellites_lost: int = 2
    satellites_lost_fraction: float = 0.2
    fix_lost_periods: float = 3.0
    fix_lost_min_s: float = 2.0
    # NLOS in urban canyons delays a signal by tens of metres, rarely more than 100-200 m
    max_reflection_m: float = 200.0
    # satellites reflected at once (NLOS on both sides of a street); RAIM's exclusion finds two at most
    max_reflected_together: int = 2
    # a spoofer's marks
    spoofer_cn0_rise_db: float = 3.0
    max_sky_cn0_dbhz: float = 50.0
    # but a sky covered before and usually (a fuselage, a garage, a pocket) that rises to an open sky's level is
    # the antenna uncovered: a skydiver's exit from the aircraft, a car out of a parking deck
    covered_sky_dbhz: float = 30.0
    open_sky_dbhz: float = 45.0
    equal_cn0_db: float = 2.0
    equal_min_satellites: int = 6
    equal_min_epochs: int = 3
    equal_below_level_db: float = 3.0  # equal C/N0 at the tracking floor (everything drowned) is no transmitter
    time_moved_s: float = 0.25
    # interference: robust rise of an indicator against its baseline (receiver_evidence's floors)
    interference_z: float = 6.0
    # a receiver recovers from interference within seconds to a minute (re-acquisition, its filter settling):
    # its alarms are the interference's this long after the interference detector's alarm ends
    interference_recovery_s: float = 60.0
    # and from this long before the interference detector's first alarm began (its loss must hold 3 s against a
    # reference window that ends 3 s before it): an alarm that began earlier has another cause
    interference_lead_s: float = 6.0
    # a jammed receiver's fixes against the INS: each epoch's horizontal INS-minus-GNSS position and velocity
    # within this many sigma of the filter's own innovation sigma and the receiver's jammed error (its error
    # before, the larger of its reported accuracy and the filter's sigma, grown by the thermal noise its C/N0
    # loss implies; its reported accuracy only where no C/N0 is logged), over a 3-epoch running median; and
    # the mean departure over that stretch within `jammed_bias_sigma` of it (noise averages out, a drag not)
    jammed_bound_sigma: float = 3.0
    jammed_bias_sigma: float = 1.0
    jammed_bias_min_epochs: int = 5
    # convergence
    converge_within_s: float = 180.0  # the first minutes after the first fix
    settle_after_s: float = 120.0  # the settled level: the fixes after this long (else the later half)
    restart_gap_s: float = 10.0
    unsettled_s: float = 10.0  # the first fixes (at most `first_fixes` within this) differ from the settled level
    first_fixes: int = 3
    # mode switch
    mode_switch_within_s: float = 3.0
    max_mode_switch_jump_m: float = 30.0
    # a fix held through an outage: frozen while the receiver reports at least this speed; the catch-up within
    # this fraction of the distance its speed covered (or a tenth of a reflection's length)
    held_min_speed_mps: float = 1.0
    held_catch_up_tolerance: float = 0.3
    held_catch_up_fixes: int = 3
    # time faults
    rollover_tolerance_s: float = 60.0
    max_leap_s: int = 18  # GPS - UTC since 2017
    leap_tolerance_s: float = 0.02
    # a fix skipped (or repeated) by an output cycle of its own: one interval's excess over the velocity is
    # a whole fix period's travel along the track (1 or 2 of them), to a quarter of it, and stands alone
    skipped_fix_tolerance: float = 0.25
    skipped_fix_max_periods: int = 2
    skipped_fix_min_travel_m: float = 1.0  # slower, a fix period's travel is lost in the fixes' noise
    repeated_fix_m: float = 0.05  # a fix sent twice: the same position, to the log's decimals
    # a satellite never used
    never_used_fraction: float = 0.05
    never_used_min_epochs: int = 30
    never_used_from_start_s: float = 30.0
    # an inertial shock: what no flight reads (ArduPilot's acro rates default to 360 deg/s; consumer gyros
    # saturate at 2000 deg/s, accelerometers at 16 g), on `shock_min_samples` samples of one IMU
    shock_rate_dps: float = 1000.0
    shock_force_g: float = 6.0
    shock_min_samples: int = 2
    shock_merge_s: float = 1.0  # shock samples closer than this are one episode
    # the inertial alarm's statistic still quiet at most this long before the shock's first sample (the
    # autopilot logs its filter at 10-25 Hz), and first beyond its level after the shock began
    shock_quiet_before_s: float = 1.0
    shock_alarm_within_s: float = 5.0  # the alarm begins within this after the shock's end
    # and ends within this after it: a filter that lost its attitude re-converges on GNSS within seconds
    # (ArduPilot's in about 10 s); a departure that outlasts this is not the shock's
    shock_recovery_s: float = 20.0
    # a glitch: GNSS leaves the coasted INS and comes back. Autopilots ride out exactly this: ArduPilot's EKF3
    # rejects GNSS that leaves its prediction for up to 7 s (10 s with an airspeed sensor: gpsRetryTimeNoTAS_ms,
    # gpsRetryTimeUseTAS_ms) before it takes GNSS back as true, a real receiver's multipath or NLOS excursion;
    # alarms after the return are the filter re-converging
    max_glitch_s: float = 10.0
    glitch_recovery_s: float = 10.0
    # a known station's antenna moved and put back (handled, knocked, a mast swaying): the receiver's motion
    # against the station, integrated, no more than a hand moves an antenna and back within this, all its
    # satellites' rates agreeing on that one motion
    max_antenna_move_m: float = 5.0
    max_antenna_move_s: float = 30.0
    antenna_back_m: float = 0.5  # or this share of the largest distance
    antenna_back_fraction: float = 0.3
    antenna_settle_s: float = 5.0  # read on to this long after the alarm
    antenna_common_share: float = 0.5  # each satellite's rate within this share of the motion's speed of it


@dataclass(frozen=True)
class Excursion:
    """GNSS away from the coasted INS and back (a confirmed coast's departure and its end)."""

    departure_s: float
    end_s: float
    peak_m: float

    @property
    def length_s(self) -> float:
        return self.end_s - self.departure_s


@dataclass(frozen=True)
class Reading:
    """One signature read on one alarm: whether it holds, and the one line and facts saying why."""

    cause: str
    kind: Kind
    held: bool
    text: str
    facts: tuple[str, ...] = ()
    receiver_id: str | None = None
    until_s: float | None = None  # held for the alarm from its start up to this time only (None: all of it)


@dataclass(frozen=True)
class Innovations:
    """The GNSS/INS filter's horizontal INS-minus-GNSS innovations and its own 1-sigma (per axis)."""

    receiver_id: str | None
    t: FloatArray
    position_m: FloatArray  # (N,) horizontal distance
    position_sigma_m: FloatArray
    velocity_mps: FloatArray
    velocity_sigma_mps: FloatArray
    position_en: FloatArray  # (N, 2) east, north: the mean of these is a drift
    velocity_en: FloatArray

    @classmethod
    def of(cls, results: Sequence[DetectorResult]) -> Innovations | None:
        nav = next((r for r in results if r.name == NAVIGATION and r.ran), None)
        if nav is None:
            return None
        series = {x.name: x for x in nav.series}
        names = ("innovation_position", "innovation_velocity")
        if any(n not in series or n + "_sigma" not in series for n in names):
            return None
        p, v = series["innovation_position"], series["innovation_velocity"]
        ps, vs = series["innovation_position_sigma"], series["innovation_velocity_sigma"]
        pe, ve = np.asarray(p.values, float)[:, :2], np.asarray(v.values, float)[:, :2]

        def per_axis(x: object) -> FloatArray:
            a = np.asarray(x, float)[:, :2]
            return np.asarray(np.sqrt(np.mean(a**2, axis=1)), float)

        rid = nav.extras.get("receiver_id")
        return cls(
            str(rid) if rid is not None else None,
            np.asarray(p.t, float),
            np.hypot(pe[:, 0], pe[:, 1]),
            per_axis(ps.values),
            np.hypot(ve[:, 0], ve[:, 1]),
            per_axis(vs.values),
            pe,
            ve,
        )


@dataclass(frozen=True)
class Shock:
    """An episode of the IMU reading what no flight reads: a tumble or an impact."""

    imu_id: str
    start_s: float
    end_s: float
    rate_dps: float  # largest angular rate
    force_g: float  # largest specific force


def inertial_shocks(table: EpochTable, opts: ExplanationOptions) -> list[Shock]:
    """Every IMU's shock episodes, in time order."""
    imu = table.imu
    if not len(imu):
        return []
    out = []
    for imu_id, rows in imu.groupby("imu_id", sort=True):
        rows = rows.sort_values("t_s")
        t = rows["t_s"].to_numpy(dtype=float)
        rate = np.degrees(np.linalg.norm(rows[["wx_radps", "wy_radps", "wz_radps"]].to_numpy(dtype=float), axis=1))
        force = np.linalg.norm(rows[["ax_mps2", "ay_mps2", "az_mps2"]].to_numpy(dtype=float), axis=1) / 9.80665
        k = np.flatnonzero((np.nan_to_num(rate) >= opts.shock_rate_dps) | (np.nan_to_num(force) >= opts.shock_force_g))
        if not len(k):
            continue
        for part in np.split(k, np.flatnonzero(np.diff(t[k]) > opts.shock_merge_s) + 1):
            if len(part) >= opts.shock_min_samples:
                span = slice(part[0], part[-1] + 1)
                out.append(
                    Shock(
                        str(imu_id),
                        float(t[part[0]]),
                        float(t[part[-1]]),
                        float(np.nanmax(rate[span])),
                        float(np.nanmax(force[span])),
                    )
                )
    return sorted(out, key=lambda x: x.start_s)


@dataclass
class _Scene:
    table: EpochTable
    results: Sequence[DetectorResult]
    opts: ExplanationOptions
    receivers: dict[str, Receiver] = field(default_factory=dict)
    # the incident being weighed, from its first alarm to its end: interference is read over all of it
    span: tuple[float, float] = (0.0, 0.0)
    satellites: tuple[str, ...] = ()  # every satellite its detectors named
    innovations: Innovations | None = None
    innovations_read: bool = False
    # where the reconstruction stage's coasts confirmed GNSS departing from the coasted INS
    departures_s: tuple[float, ...] = ()
    # ... and the ones where GNSS came back to it, each read as a glitch or not (`read_glitch`)
    excursions: tuple[Excursion, ...] = ()
    glitches: dict[Excursion, Reading] = field(default_factory=dict)

    def nav(self) -> Innovations | None:
        if not self.innovations_read:
            self.innovations, self.innovations_read = Innovations.of(self.results), True
        return self.innovations

    _shocks: list[Shock] | None = None

    @property
    def shocks(self) -> list[Shock]:
        if self._shocks is None:
            self._shocks = inertial_shocks(self.table, self.opts)
        return self._shocks

    def rx(self, rid: str) -> Receiver:
        if rid not in self.receivers:
            self.receivers[rid] = Receiver.of(self.table, rid)
        return self.receivers[rid]

    def receivers_of(self, alarm: Alarm) -> list[str]:
        return [alarm.receiver_id] if alarm.receiver_id else self.table.receivers()

    def incident_window(self, rid: str) -> Window:
        """The incident itself, no lead: interference that ended before it explains none of its alarms."""
        return Window.of(self.rx(rid), self.span[0], self.span[1] + self.opts.window_after_s)

    def window(self, alarm: Alarm, rid: str) -> Window:
        start = min(alarm.start_s, alarm.onset_s if alarm.onset_s is not None else alarm.start_s)
        return Window.of(self.rx(rid), start, alarm.end_s + self.opts.window_after_s, self.opts.window_before_s)


def _db(x: float) -> str:
    return f"{x:+.1f} dB"


def uncovered(w: Window, opts: ExplanationOptions) -> bool:
    """The sky covered before the window and for most of the log, at an open sky's level in the window, and no
    satellite lost from the fix (an antenna uncovered sees more of the sky, never less)."""
    before, usual, now = w.cn0_level_before(), w.cn0_usual_level(), w.cn0_level_now()
    kept = not w.worst("sats_used", -1) < w.level("sats_used")  # NaN (not logged) keeps
    return before < opts.covered_sky_dbhz and usual < opts.covered_sky_dbhz and now <= opts.open_sky_dbhz and kept


def weighed_marks(w: Window, opts: ExplanationOptions) -> list[SpooferMark]:
    """What a spoofer's signal does to the receiver's indicators and nature does not, each with whether it is
    a strong mark: all but a C/N0 risen by a few dB, which bars a natural reading but is no sign of its own (a
    sky returning after a loss of fix does it)."""
    marks = []
    if w.spoofing_flag_raised():
        flag = "the receiver's own spoofing flag was raised"
        marks.append(SpooferMark(flag, flag, True))
    strongest = w.worst("cn0_mean_dbhz", +1)
    if strongest > opts.max_sky_cn0_dbhz:
        above = f"mean C/N0 up to {strongest:.1f} dB-Hz, more than the sky gives ({opts.max_sky_cn0_dbhz:g})"
        marks.append(SpooferMark(above, above, True))
    _, rise, what = w.cn0_change_db()
    if rise >= opts.spoofer_cn0_rise_db and not uncovered(w, opts):
        stronger = "a stronger signal than the sky's"
        risen = f"{what} rose {_db(rise)} above its level {w.base_where} and its usual level: {stronger}"
        marks.append(SpooferMark(risen, stronger, False))
    equal = w.equal_cn0(opts.equal_cn0_db, opts.equal_min_satellites, opts.equal_min_epochs)
    if equal is not None and not equal[1] < w.cn0_level_before() - opts.equal_below_level_db:
        spread = f"{opts.equal_min_satellites} or more satellites at one C/N0 (spread {equal[0]:.1f} dB)"
        marks.append(SpooferMark(f"{spread}: one transmitter", "one transmitter", True))
    offset = w.rx.col("time_offset_s")
    if w.base is not None and np.isfinite(offset[w.now]).any():
        moved = w.worst("time_offset_s", +1) - w.level("time_offset_s")
        moved_back = w.worst("time_offset_s", -1) - w.level("time_offset_s")
        step = moved if abs(moved) >= abs(moved_back) else moved_back
        if abs(step) >= opts.time_moved_s + w.rx.time_resolution_s:  # a coarse time saws by its resolution
            moved_text = f"the receiver's time moved {step:+.3f} s against the log's clock"
            marks.append(SpooferMark(moved_text, moved_text, True))
    return marks


def spoofer_marks(w: Window, opts: ExplanationOptions) -> list[str]:
    """Every mark a spoofer's signal leaves on the receiver's indicators (`weighed_marks`)."""
    return [m.text for m in weighed_marks(w, opts)]


@dataclass(frozen=True)
class Sign:
    """One sign of a weakened sky: a few words for the one-line text, and the measurement it rests on."""

    short: str  # "C/N0 -8.1 dB"
    fact: str  # "each satellite's C/N0 fell -8.1 dB below its level before"
    kind: str = ""  # "geometry" (DOP or reported accuracy up), "satellites" (satellites used lost)


def _ratio_sign(w: Window, column: str, label: str, ratio: float, min_rise: float, unit: str = "") -> Sign | None:
    base, worst = w.level(column), w.worst(column, +1)
    if not (np.isfinite(base) and np.isfinite(worst)) or base <= 0:
        return None
    if worst >= ratio * base and worst - base >= min_rise:
        return Sign(
            f"{label} x{worst / base:.1f}",
            f"{label} {base:.2f}{unit} -> {worst:.2f}{unit} (x{worst / base:.1f})",
            "geometry",
        )
    return None


def degradation_signs(w: Window, opts: ExplanationOptions) -> tuple[list[Sign], float]:
    """The signs of a weakened or blocked sky, and the C/N0 drop (NaN when the receiver logs none; the
    least that counts when the sky was weak all along)."""
    signs = []
    drop, _, what = w.cn0_change_db()
    level = w.cn0_level_now()
    if drop >= opts.min_cn0_drop_db:
        signs.append(Sign(f"C/N0 {_db(-drop)}", f"{what} fell {drop:.1f} dB below its level {w.base_where}"))
    elif level < opts.weak_sky_dbhz and not w.cn0_level_before() >= opts.weak_sky_dbhz:
        short = f"a weak sky all along: C/N0 {level:.1f} dB-Hz"
        signs.append(Sign(short, f"{short} (an open sky gives 30-50)"))
        drop = opts.min_cn0_drop_db  # at the tracking floor no further fall is needed to lose satellites
    geometry = (
        _ratio_sign(w, "hdop", "HDOP", opts.dop_ratio, opts.dop_min_rise)
        or _ratio_sign(w, "h_acc_m", "reported accuracy", opts.accuracy_ratio, opts.accuracy_min_rise_m, " m")
        or _ratio_sign(w, "vdop", "VDOP", opts.dop_ratio, opts.dop_min_rise)
    )
    if geometry:
        signs.append(geometry)
    used, fewest = w.level("sats_used"), w.worst("sats_used", -1)
    lost = used - fewest if np.isfinite(used) and np.isfinite(fewest) else 0.0
    if lost >= max(opts.min_satellites_lost, opts.satellites_lost_fraction * used):
        text = f"satellites used {used:.0f} -> {fewest:.0f}"
        signs.append(Sign(text, text, "satellites"))
    gap = w.longest_gap_s()
    if gap >= max(opts.fix_lost_min_s, opts.fix_lost_periods * w.rx.period_s):
        text = f"fix lost for {gap:.1f} s"
        signs.append(Sign(text, text))
    return signs, drop


def _robust_rise(
    w: Window, column: str, floor: float, relative: float, direction: int, z: float
) -> tuple[float, float] | None:
    """(baseline, worst) of an indicator that moved `z` robust sigma in `direction` (+1 up, -1 down), else None."""
    now, base = w.values(column)
    if base is None:
        return None
    base = base[np.isfinite(base)]
    if len(base) < 3 or not np.isfinite(now).any():
        return None
    med = float(np.median(base))
    scale = max(1.4826 * float(np.median(np.abs(base - med))), floor, relative * abs(med))
    worst = w.worst(column, direction)
    return (med, worst) if (worst - med) * direction >= z * scale else None


def receiver_interference_signs(w: Window, z: float) -> list[str]:
    """What the receiver itself says drowned its signals: its jamming state at warning or worse, a jump of
    its jamming indicator or noise, its gain turned down."""
    signs = []
    state = w.values("jamming_state")[0]
    if (np.nan_to_num(state) >= 2).any():
        signs.append(f"the receiver's own jamming state at warning or worse ({int(np.nanmax(state))})")
    for column, label, floor, relative, direction in (
        ("jamming_indicator", "jamming indicator", 3.0, 0.1, +1),
        ("noise_per_ms", "noise level", 2.0, 0.03, +1),
        # a strong signal in the band makes the receiver turn its gain down (u-blox agcCnt, PX4 AGC); the
        # gain going up is less power at the antenna (a covered antenna, the cold), no interference
        ("agc", "AGC", 10.0, 0.03, -1),
    ):
        moved = _robust_rise(w, column, floor, relative, direction, z)
        if moved is not None:
            signs.append(f"{label} {moved[0]:.0f} -> {moved[1]:.0f}")
    return signs


def interference_signs(scene: _Scene, rid: str) -> list[str]:
    """What says something drowned the signals at the receiver's antenna over the incident: the interference
    detector's alarms, and the receiver's own signs."""
    w = scene.incident_window(rid)
    signs = []
    for r in scene.results:
        if r.evidence != Evidence.INTERFERENCE or not r.ran or r.advisory:
            continue
        near = [
            a
            for a in r.alarms
            if a.start_s <= w.end_s and a.end_s >= w.start_s and a.receiver_id in (None, w.rx.receiver_id)
        ]
        if near:
            signs.append(f"{r.name} alarmed from {near[0].start_s:.1f} s")
    return signs + receiver_interference_signs(w, scene.opts.interference_z)


def _kept(cause: str, kind: Kind, why: str, rid: str | None) -> Reading:
    return Reading(cause, kind, False, why, receiver_id=rid)


def read_degradation(scene: _Scene, alarm: Alarm, w: Window, marks: list[str], fix_alarm: bool) -> Reading:
    opts, rid = scene.opts, w.rx.receiver_id
    signs, drop = degradation_signs(w, opts)
    facts = [sg.fact for sg in signs]
    if marks:
        return _kept("degradation", Kind.DEGRADATION, "; ".join(marks), rid)
    if interference_signs(scene, rid):
        return _kept("degradation", Kind.DEGRADATION, "the receiver's interference indicators moved too", rid)
    # satellites set or blocked whole (terrain, a structure, the vehicle's own body in a bank) leave the C/N0
    # of those still tracked where it was: fewer satellites and the DOP up with them need no fall
    steady = bool(np.isfinite(drop) and drop < opts.min_cn0_drop_db)
    if steady and not {"geometry", "satellites"} <= {sg.kind for sg in signs}:
        also = f"; only {'; '.join(facts)}" if facts else ""
        return _kept("degradation", Kind.DEGRADATION, f"the C/N0 did not fall ({_db(-drop)}){also}", rid)
    if len(signs) < 2:
        why = f"one sign of a weakened sky alone ({facts[0]})" if facts else "no sign of a weakened sky"
        return _kept("degradation", Kind.DEGRADATION, why, rid)
    jump = w.largest_jump_m()
    if jump > opts.max_reflection_m:
        why = f"the fix jumped {jump:,.0f} m, more than multipath or NLOS moves it ({opts.max_reflection_m:g} m)"
        return _kept("degradation", Kind.DEGRADATION, why, rid)
    moved = " while the fix jumped" if fix_alarm else ""
    cause = "degradation (multipath, obstruction)"
    if steady:
        facts.append(f"the C/N0 of the satellites still tracked steady ({_db(-drop)})")
        moved = f", the C/N0 steady{moved}"
        cause = "fewer satellites in view (set, or blocked by terrain or a structure)"
    text = f"{_join([sg.short for sg in signs])}{moved}: {cause}, not spoofing"
    if fix_alarm:
        facts.append(f"largest jump of the fix beyond its velocity {jump:.1f} m")
    return Reading("degradation", Kind.DEGRADATION, True, text, tuple(facts), rid)


def _join(parts: list[str]) -> str:
    return parts[0] if len(parts) == 1 else ", ".join(parts[:-1]) + " and " + parts[-1]


def clean_until(scene: _Scene, alarm: Alarm, rid: str) -> float | None:
    """The latest time up to which the alarm's window shows none of a spoofer's marks (None: not even at the
    alarm's first fix). The marks only accumulate as the window grows, so the time is found by bisection."""
    rx = scene.rx(rid)
    start = min(alarm.start_s, alarm.onset_s if alarm.onset_s is not None else alarm.start_s)
    t = rx.t[(rx.t >= alarm.start_s) & (rx.t <= alarm.end_s)]

    def clean(k: int) -> bool:
        w = Window.of(rx, start, float(t[k]), scene.opts.window_before_s)
        return w.fixes == 0 or not spoofer_marks(w, scene.opts)

    if not len(t) or not clean(0):
        return None
    lo, hi = 0, len(t) - 1
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if clean(mid):
            lo = mid
        else:
            hi = mid - 1
    return float(t[lo])


def read_interference(scene: _Scene, alarm: Alarm, w: Window, marks: list[str]) -> Reading:
    rid = w.rx.receiver_id
    signs = interference_signs(scene, rid)
    if not signs:
        return _kept("interference", Kind.JAMMING, "", rid)
    until = None
    if marks:
        # a takeover after the jamming: the alarm's stretch before the spoofer's first mark is the jamming's
        until = clean_until(scene, alarm, rid)
        if until is not None and until >= alarm.end_s:
            # the mark shows just after the alarm's last epoch: its last seconds are the takeover's
            until = alarm.end_s - scene.opts.window_after_s
        if until is None or until <= alarm.start_s:
            return _kept("interference", Kind.JAMMING, "; ".join(marks), rid)
        w = Window.of(w.rx, w.start_s + scene.opts.window_before_s, until, scene.opts.window_before_s)
    stops = ["; ".join(marks)] if until is not None else []
    began = interference_start_s(scene, rid)
    if began is not None and alarm.start_s < began - scene.opts.interference_lead_s:
        return _kept("interference", Kind.JAMMING, f"the alarm began before the interference ({began:.1f} s)", rid)
    # an alarm that outlasts the interference detector's alarms is accounted for while they last and while
    # the receiver recovers (re-acquires, its filter settles), not beyond
    ended = interference_end_s(scene, rid)
    recovered = ended + scene.opts.interference_recovery_s if ended is not None else None
    if recovered is not None and alarm.end_s > recovered:
        if recovered <= alarm.start_s:
            return _kept("interference", Kind.JAMMING, f"the interference ended at {ended:.1f} s", rid)
        if until is None or recovered < until:
            until = recovered
            stops = [f"the interference ended at {ended:.1f} s"]
    effects, _ = degradation_signs(w, scene.opts)
    with_effects = " with " + _join([sg.short for sg in effects]) if effects else ""
    text = f"{_join(signs)}{with_effects}: interference, not spoofing"
    facts = (*signs, *(sg.fact for sg in effects))
    if until is not None:
        text += f" (until {until:.1f} s; then {'; '.join(stops)})"
        facts = (*facts, f"accounts for the alarm until {until:.1f} s, not after: {'; '.join(stops)}")
    return Reading("interference", Kind.JAMMING, True, text, facts, rid, until)


def interference_alarms(results: Sequence[DetectorResult]) -> list[Alarm]:
    """The counted alarms of the interference detector."""
    return [a for r in results if r.evidence == Evidence.INTERFERENCE and r.ran and not r.advisory for a in r.alarms]


def _interference_alarms_over(scene: _Scene, rid: str) -> list[Alarm]:
    """The interference detector's alarms over the incident for this receiver."""
    w = scene.incident_window(rid)
    return [
        a
        for a in interference_alarms(scene.results)
        if a.start_s <= w.end_s and a.end_s >= w.start_s and a.receiver_id in (None, rid)
    ]


def interference_end_s(scene: _Scene, rid: str) -> float | None:
    """The end of the interference detector's alarms over the incident for this receiver (None: none)."""
    return max((a.end_s for a in _interference_alarms_over(scene, rid)), default=None)


def interference_start_s(scene: _Scene, rid: str) -> float | None:
    """The earliest the interference detector's alarms over the incident say it began (None: none)."""
    return min((alarm_began(a) for a in _interference_alarms_over(scene, rid)), default=None)


def alarm_began(alarm: Alarm) -> float:
    """The earliest the alarm says its cause began: its onset interval's start, its onset, its first alarm."""
    lo = alarm.onset_interval_s[0] if alarm.onset_interval_s else alarm.start_s
    return min(lo, alarm.onset_s if alarm.onset_s is not None else alarm.start_s, alarm.start_s)


def _interp(t: FloatArray, tx: FloatArray, x: FloatArray) -> FloatArray:
    ok = np.isfinite(x)
    if not ok.any():
        return np.full(len(t), np.nan)
    return np.interp(t, tx[ok], x[ok])


def _cn0_drop_at(w: Window, t: FloatArray) -> tuple[FloatArray, str]:
    """The C/N0's fall against its level before at times `t` (per satellite where the sky is logged, else the
    mean C/N0), and what it was read from."""
    per_sat = w.satellite_cn0_change()
    if np.isfinite(per_sat).any():
        return -_interp(t, w.rx.sky.t[w.sky_now], per_sat), "each satellite's C/N0"
    base = w.level("cn0_mean_dbhz")
    if not np.isfinite(base):
        return np.full(len(t), np.nan), ""
    x = running_median(w.rx.col("cn0_mean_dbhz")[w.now])
    return base - _interp(t, w.rx.t[w.now], x), "mean C/N0"


def read_jammed_fixes(scene: _Scene, alarm: Alarm) -> Reading:
    """An inertial alarm under interference where GNSS departed from the INS no more than the jammed
    receiver's error allows (its error before grown by the thermal noise its C/N0 loss implies; what it
    reports of its accuracy only where no C/N0 is logged), on top of the filter's own sigma; and without a
    steady drift. Held up to the first epoch that departs further (or shows a spoofer's mark), not beyond."""
    cause, opts = JAMMED, scene.opts
    nav = scene.nav()
    rid = (nav.receiver_id if nav is not None else None) or alarm.receiver_id or next(iter(scene.table.receivers()), "")
    if nav is None or rid not in scene.table.receivers():
        return _kept(cause, Kind.JAMMING, "", rid)
    signs = interference_signs(scene, rid)
    if not signs:
        return _kept(cause, Kind.JAMMING, "", rid)
    w = scene.window(alarm, rid)
    sel = (nav.t >= alarm.start_s) & (nav.t <= alarm.end_s) & np.isfinite(nav.position_m)
    t = nav.t[sel]
    if not len(t) or w.fixes == 0:
        return _kept(cause, Kind.JAMMING, "", rid)
    rx = w.rx
    drop, what = _cn0_drop_at(w, t)
    # the thermal noise a C/N0 loss of `drop` dB adds, against the noise before: sqrt(10^(drop/10) - 1)
    thermal = np.sqrt(np.maximum(10.0 ** (np.nan_to_num(drop, nan=0.0) / 10.0) - 1.0, 0.0))
    thermal = np.where(np.isfinite(drop), thermal, np.nan)
    ratios, errors = [], []
    for dist, sigma, column in (
        (nav.position_m[sel], nav.position_sigma_m[sel], "h_acc_m"),
        (nav.velocity_mps[sel], nav.velocity_sigma_mps[sel], "vel_acc_mps"),
    ):
        claimed = _interp(t, rx.t, rx.col(column))
        # the receiver's error before (what it claimed then, or the filter's own innovation sigma learned on
        # the clean log, whichever is more: receivers understate their velocity noise), grown as its C/N0
        # loss grows thermal noise; what it claims now only where its C/N0 is not logged (a spoofer can
        # inflate a claim, not the sky's C/N0 loss)
        implied = np.fmax(w.level(column), sigma) * thermal
        error = np.where(np.isfinite(implied), implied, claimed)
        allowed = opts.jammed_bound_sigma * np.hypot(sigma, np.nan_to_num(error, nan=0.0))
        ratios.append(running_median(np.where(np.isfinite(dist), dist / allowed, 0.0)))
        errors.append((dist, claimed, implied, allowed))
    ratio = np.fmax(ratios[0], ratios[1])
    beyond = np.flatnonzero(~(ratio <= 1.0))
    n = int(beyond[0]) if len(beyond) else len(t)
    if n == 0:
        k = int(np.nanargmax(ratio))
        why = (
            f"GNSS departed from the INS {errors[0][0][k]:.1f} m and {errors[1][0][k]:.2f} m/s at {t[k]:.1f} s, "
            f"{ratio[k]:.1f} x what the receiver's reported accuracy or its C/N0 loss allows"
        )
        return _kept(cause, Kind.JAMMING, why, rid)
    if n >= opts.jammed_bias_min_epochs:
        for (_, _, _, allowed), en, unit in (
            (errors[0], nav.position_en[sel], "m"),
            (errors[1], nav.velocity_en[sel], "m/s"),
        ):
            bias = float(np.hypot(*np.nanmean(en[:n], axis=0)))
            scale = float(np.nanmean(allowed[:n])) / opts.jammed_bound_sigma
            if bias > opts.jammed_bias_sigma * scale:
                why = f"GNSS drifted from the INS steadily (mean {bias:.2f} {unit}, the receiver's error {scale:.2f})"
                return _kept(cause, Kind.JAMMING, why, rid)
    until = float(t[n - 1]) if n < len(t) else None
    stops = []
    if n < len(t):
        stops.append(f"GNSS departed further from {t[n]:.1f} s")
    mark_free = clean_until(scene, alarm, rid) if spoofer_marks(w, opts) else alarm.end_s
    if mark_free is None:
        return _kept(cause, Kind.JAMMING, "; ".join(spoofer_marks(w, opts)), rid)
    if mark_free < (until if until is not None else alarm.end_s):
        until = mark_free
        stops.append(f"a spoofer's mark from {mark_free:.1f} s")
    if until is not None and until <= alarm.start_s:
        return _kept(cause, Kind.JAMMING, "; ".join(stops), rid)
    m = slice(0, n)
    (dp, cp, _, ap), (dv, cv, _, av) = errors
    drop_max = float(np.nanmax(drop[m])) if np.isfinite(drop[m]).any() else float("nan")
    claimed_text = (
        f"reported accuracy up to {np.nanmax(cp[m]):.1f} m and {np.nanmax(cv[m]):.2f} m/s"
        if np.isfinite(cp[m]).any() and np.isfinite(cv[m]).any()
        else "no reported accuracy"
    )
    facts = [
        f"GNSS minus INS at most {np.nanmax(dp[m]):.1f} m and {np.nanmax(dv[m]):.2f} m/s "
        f"from {t[0]:.1f} s to {t[n - 1]:.1f} s",
        claimed_text,
        f"allowed up to {np.nanmax(ap[m]):.1f} m and {np.nanmax(av[m]):.2f} m/s "
        f"({opts.jammed_bound_sigma:g} sigma of the filter's own and the jammed receiver's error)",
        f"{what} down {drop_max:.1f} dB (thermal noise x{np.nanmax(thermal[m]):.1f})"
        if np.isfinite(drop_max)
        else "C/N0 not logged",
        *signs,
    ]
    if stops:
        facts.append(f"accounts for the alarm until {until:.1f} s, not after: {'; '.join(stops)}")
    text = (
        f"GNSS within what the jammed receiver's own error allows of the INS ({facts[0]}; {claimed_text}): "
        "a jammed receiver's noisier fixes, not spoofing" + (f" (until {until:.1f} s)" if until is not None else "")
    )
    return Reading(cause, Kind.JAMMING, True, text, tuple(facts), rid, until)


def _fix_starts(rx: Receiver, opts: ExplanationOptions) -> list[float]:
    """The receiver's first valid fix and every first fix after it was lost for `restart_gap_s` or longer."""
    valid = (rx.fix_type >= FixType.FIX_2D) & np.isfinite(rx.col("lat_deg"))
    tv = rx.t[valid]
    if not len(tv):
        return []
    gap = np.diff(tv) >= max(opts.restart_gap_s, 5.0 * rx.period_s)
    return [float(tv[0]), *tv[1:][gap].tolist()]


def _settled_at(t: FloatArray, off: BoolArray, window: BoolArray, opts: ExplanationOptions) -> float:
    """When the run of fixes off their settled level that a start begins with ended (NaN when the first
    fixes were at it). Only that first run: a receiver converges once, and a later stretch off level in
    the same minutes (interference, an obstruction) is another event, not a longer convergence."""
    idx = np.flatnonzero(window)
    flags = off[idx]
    began = np.flatnonzero(flags[: opts.first_fixes])
    if not len(began):
        return float("nan")
    back = np.flatnonzero(~flags[began[0] :])
    last = began[0] + back[0] - 1 if len(back) else len(flags) - 1
    return float(t[idx[last]])


def read_convergence(scene: _Scene, alarm: Alarm, w: Window, marks: list[str]) -> Reading:
    opts, rx = scene.opts, w.rx
    rid = rx.receiver_id
    every_start = _fix_starts(rx, opts)
    starts = [s for s in every_start if s <= alarm.start_s]
    if not starts or min(alarm.start_s, alarm.onset_s or alarm.start_s) > starts[-1] + opts.converge_within_s:
        return _kept("convergence", Kind.RECEIVER_FAULT, "", rid)
    s0 = starts[-1]
    later = [s for s in every_start if s > s0]
    stop = later[0] if later else float(rx.t[-1]) + 1.0
    span = (rx.t >= s0) & (rx.t < stop)
    settled = span & (rx.t >= s0 + opts.settle_after_s)
    if settled.sum() < 10:
        idx = np.flatnonzero(span)
        settled = np.zeros(len(rx.t), bool)
        settled[idx[len(idx) // 2 :]] = True
    first = np.zeros(len(rx.t), bool)
    first[np.flatnonzero(span & (rx.t <= s0 + opts.unsettled_s))[: opts.first_fixes]] = True
    unsettled: list[str] = []
    final = float("nan")
    for column, label, ratio, rise, direction in (
        ("hdop", "HDOP", 1.5, 0.5, +1),
        ("h_acc_m", "reported accuracy (m)", 2.0, 2.0, +1),
        ("sats_used", "satellites used", 0.75, 2.0, -1),
    ):
        x = rx.col(column)
        level = float(np.nanmedian(x[settled])) if np.isfinite(x[settled]).any() else float("nan")
        if not np.isfinite(level) or not np.isfinite(x[first]).any():
            continue
        # the first fixes' middle value: one of them off alone is the sky's own flicker (a car's 9, 7, 9
        # satellites against 11 later was no cold start), a receiver converging has them all off
        start = float(np.nanmedian(x[first]))
        if direction > 0:
            off = start >= ratio * level and start - level >= rise
        else:
            off = start <= ratio * level and level - start >= rise
        if off:
            digits = 0 if column == "sats_used" else 1
            unsettled.append(f"{label} {start:.{digits}f} -> {level:.{digits}f}")
            run = running_median(x)
            far = (run > max(ratio, 1.25) * level + 0.2) if direction > 0 else (run < level - 1.0)
            final = float(np.fmax(final, _settled_at(rx.t, far, span & (rx.t <= s0 + opts.converge_within_s), opts)))
    kinds = rx.fix_type[span & (rx.fix_type >= FixType.FIX_2D)]
    settled_kind = int(np.median(rx.fix_type[settled])) if settled.any() else None
    if settled_kind is not None and len(kinds) and int(kinds[0]) < settled_kind:
        unsettled.append(
            f"{FIX_NAMES.get(FixType(int(kinds[0])), 'fix')} -> {FIX_NAMES.get(FixType(settled_kind), 'fix')}"
        )
        worse = rx.fix_type < settled_kind
        final = float(np.fmax(final, _settled_at(rx.t, worse, span & (rx.t <= s0 + opts.converge_within_s), opts)))
    after_loss = s0 > every_start[0]
    how = f"its fix back at {s0:.1f} s" if after_loss else f"its first fix at {s0:.1f} s"
    if not unsettled:
        return _kept("convergence", Kind.RECEIVER_FAULT, f"the receiver was already settled at {how}", rid)
    if marks:
        return _kept("convergence", Kind.RECEIVER_FAULT, "; ".join(marks), rid)
    settled_by = final if np.isfinite(final) else s0
    if alarm.start_s > settled_by + opts.unsettled_s:
        return _kept(
            "convergence",
            Kind.RECEIVER_FAULT,
            f"the alarm came at {alarm.start_s:.1f} s, after the receiver had settled ({settled_by:.1f} s)",
            rid,
        )
    facts = (how, *unsettled, f"settled by {settled_by:.1f} s")
    what = "converging after a cold start" if not after_loss else "re-converging after the fix was lost"
    text = f"{_join(unsettled)} from {how} until {settled_by:.1f} s: {what}, not spoofing"
    return Reading("convergence", Kind.RECEIVER_FAULT, True, text, facts, rid)


def read_mode_switch(scene: _Scene, alarm: Alarm, w: Window, marks: list[str]) -> Reading:
    opts, rx = scene.opts, w.rx
    rid = rx.receiver_id
    ft = rx.fix_type
    real = (ft[1:] >= FixType.FIX_2D) & (ft[:-1] >= FixType.FIX_2D) & (ft[1:] != ft[:-1])
    k = np.flatnonzero(real) + 1
    at = alarm.onset_s if alarm.onset_s is not None else alarm.start_s
    near = k[(rx.t[k] >= at - opts.mode_switch_within_s) & (rx.t[k] <= alarm.start_s + opts.mode_switch_within_s)]
    if not len(near):
        return _kept("mode switch", Kind.RECEIVER_FAULT, "", rid)
    if marks:
        return _kept("mode switch", Kind.RECEIVER_FAULT, "; ".join(marks), rid)
    i = int(near[0])
    jump = Window.of(rx, float(rx.t[i - 1]), float(rx.t[i])).largest_jump_m()
    names = (FIX_NAMES.get(FixType(int(ft[i - 1])), "fix"), FIX_NAMES.get(FixType(int(ft[i])), "fix"))
    if jump > opts.max_mode_switch_jump_m:
        why = f"the fix jumped {jump:,.0f} m at the switch, more than a mode switch moves it"
        return _kept("mode switch", Kind.RECEIVER_FAULT, why, rid)
    text = (
        f"the fix switched from {names[0]} to {names[1]} at {rx.t[i]:.1f} s, moving {jump:.1f} m: "
        "a receiver mode switch, not spoofing"
    )
    facts = (f"fix type {names[0]} -> {names[1]} at {rx.t[i]:.1f} s", f"jump at the switch {jump:.1f} m")
    return Reading("mode switch", Kind.RECEIVER_FAULT, True, text, facts, rid)


def read_held_fix(scene: _Scene, alarm: Alarm, w: Window, marks: list[str]) -> Reading:
    """A receiver that lost its satellites and kept writing its last position as a valid fix (a car's receiver
    under an overpass: quality 1, status A, 0 satellites used, its position frozen while it reported 53 kn),
    then jumped ahead to where the vehicle had got to. The held fixes are those with no satellite used, or the
    very position of the fix before while the receiver reports a speed; the jump after them must be the
    distance the reported speed covers over the hold (within `held_catch_up_tolerance`, and a reflection's
    length): a spoofer's jump is not where the vehicle's own speed took it."""
    opts, rx = scene.opts, w.rx
    rid = rx.receiver_id
    lo = max(w.now.start - 1, 0)
    idx = np.arange(lo + 1, w.now.stop)
    if not len(idx) or marks:
        return _kept(HELD_FIX, Kind.DEGRADATION, "; ".join(marks), rid)
    lat, lon, used = rx.col("lat_deg"), rx.col("lon_deg"), rx.col("sats_used")
    speed = np.hypot(rx.col("vel_e_mps"), rx.col("vel_n_mps"))
    frozen = (lat[idx] == lat[idx - 1]) & (lon[idx] == lon[idx - 1]) & (speed[idx - 1] >= opts.held_min_speed_mps)
    held = frozen | (used[idx] == 0)
    runs = np.flatnonzero(np.diff(np.r_[0, held.astype(np.int8), 0]))
    for a, b in zip(runs[::2], runs[1::2], strict=True):
        first, end = int(idx[a]), int(idx[b - 1]) + 1  # the first held fix, the fix that ends the hold
        if end >= len(rx.t) or not np.isfinite(speed[first - 1]):
            continue
        # the receiver catches up within a few fixes (a first fix on 3 satellites at HDOP 20 may lag)
        caught = None
        for after in range(end, min(end + opts.held_catch_up_fixes, len(rx.t))):
            span = float(rx.t[after] - rx.t[first - 1])
            east, north = small_move_en_m(lat[after] - lat[first - 1], lon[after] - lon[first - 1], lat[after])
            moved = float(np.hypot(east, north))
            travel = float(np.nanmean(speed[[first - 1, after]])) * span
            if abs(moved - travel) <= max(opts.held_catch_up_tolerance * travel, opts.max_reflection_m / 10):
                caught = (after, span, moved, travel)
                break
        if caught is None:
            continue
        after, span, moved, travel = caught
        n, lost = end - first, used[first:end]
        sats = f"{np.nanmin(lost):.0f} satellites used" if np.isfinite(lost).any() else "no satellite count"
        text = (
            f"the receiver held its fix for {rx.t[end] - rx.t[first]:.1f} s from {rx.t[first]:.1f} s ({sats}, its "
            f"position frozen at {speed[first - 1]:.1f} m/s), then caught up {moved:.0f} m by {rx.t[after]:.1f} s, "
            "what its speed covered: an outage (an overpass, a tunnel), not spoofing"
        )
        facts = (
            f"{n} fix(es) held at {rx.t[first]:.1f}-{rx.t[end - 1]:.1f} s ({sats})",
            f"catch-up {moved:.0f} m against {travel:.0f} m at the reported speed over {span:.1f} s",
        )
        return Reading(HELD_FIX, Kind.DEGRADATION, True, text, facts, rid)
    return _kept(HELD_FIX, Kind.DEGRADATION, "", rid)


def read_skipped_fix(scene: _Scene, alarm: Alarm, w: Window, marks: list[str]) -> Reading:
    """A fix dropped (or sent twice) by an output cycle that is not locked to the receiver's fixes (an NMEA
    2000 gateway sending 129029 every 1.005 s of 1 Hz fixes drops one every 200 s): between two messages
    the fix moved its velocity's travel plus one (or two) whole fix periods' along the track (minus one:
    repeated: the same position twice), and no other interval of the check's window moved more than half that
    beyond its velocity.
    The check's window then alarms for its own length at most."""
    opts, rx = scene.opts, w.rx
    rid = rx.receiver_id
    window_s = ConsistencyOptions().window_s
    period = rx.period_s
    at = min(alarm.start_s, alarm.onset_s if alarm.onset_s is not None else alarm.start_s)
    k = np.flatnonzero((rx.t[1:] >= at - window_s) & (rx.t[1:] <= alarm.start_s + 2.0 * period))
    if len(k) < 2:
        return _kept("skipped fix", Kind.RECEIVER_FAULT, "", rid)
    lat, lon = rx.col("lat_deg"), rx.col("lon_deg")
    east, north = small_move_en_m(np.diff(lat), np.diff(lon), np.nanmean(lat[k]))
    ve, vn, dt = rx.col("vel_e_mps"), rx.col("vel_n_mps"), np.diff(rx.t)
    me, mn = 0.5 * (ve[1:] + ve[:-1]), 0.5 * (vn[1:] + vn[:-1])
    ee, en = (east - me * dt)[k], (north - mn * dt)[k]
    excess = np.hypot(ee, en)
    if not np.isfinite(excess).all():
        return _kept("skipped fix", Kind.RECEIVER_FAULT, "", rid)
    order = np.argsort(-excess)
    i, j = int(order[0]), int(order[1])
    te, tn = me[k[i]] * period, mn[k[i]] * period  # one fix period's travel
    travel = float(np.hypot(te, tn))
    if travel < opts.skipped_fix_min_travel_m:
        return _kept("skipped fix", Kind.RECEIVER_FAULT, "", rid)
    n = round(float(ee[i] * te + en[i] * tn) / travel**2)
    miss = float(np.hypot(ee[i] - n * te, en[i] - n * tn))
    when = float(rx.t[k[i] + 1])
    moved = float(np.hypot(east[k[i]], north[k[i]]))
    if (
        n == 0
        or abs(n) > opts.skipped_fix_max_periods
        or miss > opts.skipped_fix_tolerance * travel
        or (n < 0 and moved > opts.repeated_fix_m)  # a fix sent twice carries the same numbers twice
    ):  # no jump of whole fix periods: not this cause (nothing to list)
        return _kept("skipped fix", Kind.RECEIVER_FAULT, "", rid)
    if excess[j] > 0.5 * travel:
        also = f"{excess[j]:.1f} m beyond its velocity at {rx.t[k[j] + 1]:.1f} s"
        why = f"the fix also moved {also}: no single dropped fix"
        return _kept("skipped fix", Kind.RECEIVER_FAULT, why, rid)
    if alarm.end_s - alarm.start_s > window_s + 3.0 * period:
        why = f"the alarm lasted {alarm.end_s - alarm.start_s:.1f} s, longer than one jump keeps the check's window"
        return _kept("skipped fix", Kind.RECEIVER_FAULT, why, rid)
    if marks:
        return _kept("skipped fix", Kind.RECEIVER_FAULT, "; ".join(marks), rid)
    what = f"{'dropped' if n > 0 else 'repeated'} {abs(n)} fix(es)"
    saws = (
        f"; its time saws by its {rx.time_resolution_s:g} s resolution the same way (receiver_time)"
        if rx.time_resolution_s > 0
        else ""
    )
    text = (
        f"the fix moved {excess[i]:.1f} m beyond its velocity at {when:.1f} s, {abs(n)} fix period(s)' travel "
        f"({travel:.1f} m per {period:.3f} s) {'ahead' if n > 0 else 'behind'}: an output cycle not locked to the "
        f"fixes {what}{saws}, not spoofing"
    )
    facts = (  # one sign: the jump, and that it stands alone
        f"jump beyond the velocity {excess[i]:.2f} m at {when:.1f} s: {n:+d} x {travel:.2f} m (one fix period's "
        f"travel), off by {miss:.2f} m",
        f"next largest in the window {excess[j]:.2f} m",
    )
    return Reading("skipped fix", Kind.RECEIVER_FAULT, True, text, facts, rid)


def read_time_fault(scene: _Scene, alarm: Alarm, rid: str) -> Reading:
    opts, rx = scene.opts, scene.rx(rid)
    x = rx.col("time_offset_s")
    onset = alarm.onset_s if alarm.onset_s is not None else alarm.start_s
    before = (rx.t >= onset - 60.0) & (rx.t < onset) & np.isfinite(x)
    during = (rx.t >= onset) & (rx.t <= alarm.end_s) & np.isfinite(x)
    if before.sum() < 3 or during.sum() < 1:
        return _kept("time fault", Kind.RECEIVER_FAULT, "", rid)
    step = float(np.median(x[during]) - np.median(x[before]))
    dx = np.diff(x[before])
    jitter = 1.4826 * float(np.median(np.abs(dx - np.median(dx)))) if len(dx) else 0.0
    weeks = round(step / ROLLOVER_S)
    if weeks != 0 and abs(step - weeks * ROLLOVER_S) <= opts.rollover_tolerance_s:
        text = (
            f"the receiver's date moved {weeks * 1024:+d} weeks ({step:+,.0f} s) against the log's clock: "
            "a GPS week rollover (10-bit week number), not spoofing"
        )
        return Reading("week rollover", Kind.RECEIVER_FAULT, True, text, (f"time step {step:+.3f} s",), rid)
    n = round(step)
    if 1 <= abs(n) <= opts.max_leap_s and abs(step - n) <= max(opts.leap_tolerance_s, 3.0 * jitter):
        text = (
            f"the receiver's UTC moved by exactly {n:+d} s against the log's clock: leap seconds applied or "
            "defaulted (GPS - UTC is 18 s since 2017), not spoofing"
        )
        return Reading("leap seconds", Kind.RECEIVER_FAULT, True, text, (f"time step {step:+.3f} s",), rid)
    return _kept(
        "time fault", Kind.RECEIVER_FAULT, f"a step of {step:+.3f} s is no whole leap second or week epoch", rid
    )


def off_together(scene: _Scene, alarm: Alarm) -> dict[str, float]:
    """The incident's other satellites named off at the same time as this alarm's (their alarms overlapping
    half or more of the shorter of the two), each with the largest range error its alarms gave (NaN when
    none gave one): a car passing buildings has its satellites reflected one after another (a phone's R14
    for 20 s, then R13), or two at once in a street; a bias moves several at once, by its own amount."""
    mine, incident = set(alarm.satellites), set(scene.satellites)
    others: dict[str, float] = {}
    for result in scene.results:
        for a in result.alarms:
            named = set(a.satellites) & incident
            if a is alarm or not named - mine:
                continue
            overlap = min(a.end_s, alarm.end_s) - max(a.start_s, alarm.start_s)
            if overlap >= 0.5 * min(a.end_s - a.start_s, alarm.end_s - alarm.start_s):
                size = a.range_error_m if a.range_error_m is not None and len(a.satellites) == 1 else np.nan
                for sv in named - mine:  # an alarm that gave no size leaves the satellite's unknown
                    before = others.get(sv, size)
                    others[sv] = np.nan if np.isnan(before) or np.isnan(size) else max(before, size)
    return dict(sorted(others.items()))


def read_reflection(scene: _Scene, alarm: Alarm, result: DetectorResult) -> Reading:
    """One satellite's range a reflection's length off (or two at once, each within it), its C/N0 not raised:
    NLOS or multipath."""
    rid = alarm.receiver_id or ""
    sv = alarm.satellites[0]
    others = off_together(scene, alarm)
    # reflections delay satellites each by its own path, two at once in a street; a third off at the same
    # time, or one off by more than a reflection or by an unknown amount, is a bias on a subset
    far = [o for o, size in others.items() if not size <= scene.opts.max_reflection_m]
    if len(others) > scene.opts.max_reflected_together - 1 or far:
        why = f"{sv} is not alone: {'+'.join(others)} off at the same time"
        return _kept("reflection", Kind.DEGRADATION, why, rid)
    # the alarm's own size (a moving receiver passes reflections: its satellites are excluded now and then,
    # in runs, rarely at most of their epochs), and that of any finding on the satellite over the alarm; the
    # largest is weighed, so a satellite found far off elsewhere in the same time stays far off
    sizes = [
        f.range_error_m
        for f in result.findings
        if f.satellites == (sv,)
        and f.range_error_m is not None
        and f.start_s <= alarm.end_s
        and f.end_s >= alarm.start_s
    ]
    if alarm.range_error_m is not None:
        sizes.append(alarm.range_error_m)
    sizes = [x for x in sizes if np.isfinite(x)]
    if not sizes:
        return _kept("reflection", Kind.DEGRADATION, "", rid)
    size = max(sizes)
    if size > scene.opts.max_reflection_m:
        why = f"{sv} was {size:,.0f} m off, more than a reflection ({scene.opts.max_reflection_m:g} m)"
        return _kept("reflection", Kind.DEGRADATION, why, rid)
    cn0 = "C/N0 not logged"
    if alarm.receiver_id:
        rx = scene.rx(alarm.receiver_id)
        if sv in rx.sky.sv and len(rx.sky.t):
            j = rx.sky.sv.index(sv)
            t, x = rx.sky.t, rx.sky.cn0[:, j]
            before = x[(t < alarm.start_s - 2.0) & (t >= alarm.start_s - 60.0)]
            during = x[(t >= alarm.start_s) & (t <= alarm.end_s)]
            if np.isfinite(before).any() and np.isfinite(during).any():
                rise = float(np.nanmax(during) - np.nanmedian(before))
                # a spoofer's signal rises above the sky's usual strength; a satellite near its tracking
                # threshold that gains a few dB is still a weak, likely reflected one (a 2016 phone's G05:
                # 14.8 -> 19.9 dB-Hz, a 30 m NLOS range, where the log's satellites sit near 30)
                above_sky = np.isnan(rx.sky.usual_cn0) or float(np.nanmax(during)) > rx.sky.usual_cn0
                if rise >= scene.opts.spoofer_cn0_rise_db and above_sky:
                    return _kept(
                        "reflection", Kind.DEGRADATION, f"{sv}'s C/N0 rose {_db(rise)}: no reflection does that", rid
                    )
                cn0 = f"its C/N0 {_db(rise)} against its level before"
    if others:
        beside = ", ".join(f"{o} {size:.0f} m" for o, size in others.items())
        text = (
            f"{sv} {size:.0f} m off, with {beside} off at the same time, each within a reflection's length, "
            f"while the other satellites agree ({cn0}): reflected signals (NLOS, multipath), not spoofing"
        )
    else:
        text = (
            f"{sv} alone {size:.0f} m off while the other satellites agree ({cn0}): a reflected signal "
            "(NLOS, multipath), not spoofing"
        )
    facts = (f"{sv} range error {size:.1f} m", *(f"{o} range error {x:.1f} m" for o, x in others.items()), cn0)
    return Reading("reflection", Kind.DEGRADATION, True, text, facts, rid)


def read_never_used(scene: _Scene, alarm: Alarm, rid: str) -> Reading:
    opts, sky = scene.opts, scene.rx(rid).sky
    facts = []
    for sv in alarm.satellites:
        if sv not in sky.sv:
            return _kept("satellite never used", Kind.UNKNOWN, "", rid)
        j = sky.sv.index(sv)
        tracked = np.isfinite(sky.cn0[:, j])
        used = sky.used[:, j][tracked]
        known = np.isfinite(used)
        first = float(sky.t[tracked][0]) if tracked.any() else float("inf")
        if (
            tracked.sum() < opts.never_used_min_epochs
            or known.mean() < 0.5
            or first > float(sky.t[0]) + opts.never_used_from_start_s
        ):
            return _kept("satellite never used", Kind.UNKNOWN, "", rid)
        fraction = float(np.mean(used[known] == 1))
        if fraction > opts.never_used_fraction:
            return _kept(
                "satellite never used",
                Kind.UNKNOWN,
                f"the receiver used {sv} at {100 * fraction:.0f}% of its epochs",
                rid,
            )
        facts.append(
            f"{sv} tracked at {int(tracked.sum())} epochs from {first:.1f} s, used in the fix at {100 * fraction:.0f}%"
        )
    names = "+".join(alarm.satellites)
    text = (
        f"the receiver never used {names} in its fix, from the log's start: a satellite left out of the fix "
        "cannot have moved it"
    )
    return Reading("satellite never used", Kind.UNKNOWN, True, text, tuple(facts), rid)


def read_inertial_shock(scene: _Scene, alarm: Alarm) -> Reading:
    """An inertial alarm that began as the IMU read a tumble or an impact: the INS, not GNSS, departed."""
    opts = scene.opts
    onset = min(alarm.start_s, alarm.onset_s if alarm.onset_s is not None else alarm.start_s)
    # a shock inside the alarm, or just before it began (one inside an alarm that rose before it is
    # weighed, and refused, so the report says why)
    near = [
        sh
        for sh in scene.shocks
        if sh.start_s - opts.shock_quiet_before_s <= alarm.end_s
        and alarm.start_s <= sh.end_s + opts.shock_alarm_within_s
    ]
    if not near:
        return _kept("inertial shock", Kind.UNKNOWN, "", None)
    sh = near[0]
    imu = sh.imu_id if sh.imu_id.upper().startswith("IMU") else f"IMU {sh.imu_id}"
    what = f"{sh.rate_dps:,.0f} deg/s and {sh.force_g:.1f} g from {sh.start_s:.1f} s to {sh.end_s:.1f} s"
    if onset < sh.start_s - opts.shock_quiet_before_s or alarm.start_s < sh.start_s:
        why = f"the inertial alarm rose from {onset:.1f} s, before the IMU read {what}"
        return _kept("inertial shock", Kind.UNKNOWN, why, None)
    if alarm.end_s > sh.end_s + opts.shock_recovery_s:
        why = (
            f"the inertial alarm lasted until {alarm.end_s:.1f} s, {alarm.end_s - sh.end_s:.0f} s after the IMU "
            f"read {what}: longer than a filter takes to re-converge ({opts.shock_recovery_s:g} s)"
        )
        return _kept("inertial shock", Kind.UNKNOWN, why, None)
    text = (
        f"{imu} read {what} (a tumble or an impact) just before the inertial alarm: the INS lost "
        "its attitude and departed from GNSS until it re-converged, not spoofing"
    )
    facts = (
        f"{imu} angular rate up to {sh.rate_dps:,.0f} deg/s, specific force up to {sh.force_g:.1f} g "
        f"({sh.start_s:.2f}-{sh.end_s:.2f} s)",
        f"the inertial alarm quiet until {onset:.2f} s, beyond its level from {alarm.start_s:.2f} s",
        f"the inertial alarm over by {alarm.end_s:.2f} s, {alarm.end_s - sh.end_s:.1f} s after the shock",
    )
    return Reading("inertial shock", Kind.UNKNOWN, True, text, facts, None)


def _excursion_around(scene: _Scene, start_s: float) -> Excursion | None:
    """The excursion an alarm interval began in: from its departure (less the lead an onset estimate takes)
    to the filter's recovery after GNSS came back. It may go on after that: a windowed test (GLRT, MLRT)
    holds its alarm while its window still spans the excursion, and the incident ends at the return."""
    return next(
        (
            e
            for e in scene.excursions
            if e.departure_s - DEPARTURE_LEAD_S <= start_s <= e.end_s + scene.opts.glitch_recovery_s
        ),
        None,
    )


def read_glitch(scene: _Scene, start_s: float) -> Reading:
    """GNSS left the coasted INS for seconds and came back onto it, with no spoofer's mark on the receivers:
    a glitch, as multipath and NLOS make, that an autopilot rides out; a spoofer who lets go within seconds
    took nothing. Held for the alarms that began inside the excursion (or the filter's recovery after it)."""
    e = _excursion_around(scene, start_s)
    if e is None:
        return Reading("glitch", Kind.DEGRADATION, False, "")
    if e not in scene.glitches:  # every alarm of the excursion reads the same
        scene.glitches[e] = _glitch(scene, e)
    return scene.glitches[e]


def _glitch(scene: _Scene, e: Excursion) -> Reading:
    if e.length_s > scene.opts.max_glitch_s:
        why = (
            f"GNSS left the coasted INS reference for {e.length_s:.1f} s before it came back, longer than a glitch an "
            f"autopilot rides out ({scene.opts.max_glitch_s:g} s)"
        )
        return Reading("glitch", Kind.DEGRADATION, False, why)
    if e.peak_m > scene.opts.max_reflection_m:
        why = f"GNSS left the coasted INS reference by {e.peak_m:,.0f} m, more than multipath or NLOS moves it"
        return Reading("glitch", Kind.DEGRADATION, False, why)
    marks = [
        m
        for rid in scene.table.receivers()
        if (w := Window.of(scene.rx(rid), e.departure_s, e.end_s)).fixes
        for m in spoofer_marks(w, scene.opts)
    ]
    if marks:
        return Reading("glitch", Kind.DEGRADATION, False, "; ".join(marks))
    facts = (f"{e.peak_m:.0f} m off the coasted INS", f"back on it after {e.length_s:.1f} s")
    why = (
        f"GNSS left the coasted INS reference by {e.peak_m:.0f} m for {e.length_s:.1f} s and came back onto it: a "
        "glitch, as multipath and NLOS make, not spoofing (no spoofer's mark on the receiver)"
    )
    return Reading("glitch", Kind.DEGRADATION, True, why, facts)


def read_antenna_moved(scene: _Scene, alarm: Alarm) -> Reading:
    """A known station's receiver moving against its known position and back, all satellites agreeing."""
    opts, rid = scene.opts, alarm.receiver_id or ""
    rates = next((r for r in scene.results if r.name == RANGE_RATE and r.ran), None)
    series = {s.name: s for s in rates.series} if rates is not None else {}
    motion, residual = series.get(f"{rid}/velocity_error"), series.get(f"{rid}/rate_residual")
    if motion is None or residual is None:
        return _kept("antenna moved", Kind.RECEIVER_FAULT, "", rid)
    t = motion.t
    a = max(int(np.searchsorted(t, alarm.start_s)) - 1, 0)
    b = int(np.searchsorted(t, alarm.end_s + opts.antenna_settle_s, side="right"))
    dv = np.nan_to_num(np.asarray(motion.values, dtype=float)[a:b])
    if b - a < 2:
        return _kept("antenna moved", Kind.RECEIVER_FAULT, "", rid)
    steps = 0.5 * (dv[1:] + dv[:-1]) * np.diff(t[a:b])[:, None]
    moved = np.linalg.norm(np.cumsum(steps, axis=0), axis=1)
    peak, back = float(moved.max()), float(moved[-1])
    lasted = alarm.end_s - alarm.start_s
    if peak > opts.max_antenna_move_m:
        why = f"the receiver moved {peak:.1f} m from the known position, more than a hand or a knock moves an antenna"
        return _kept("antenna moved", Kind.RECEIVER_FAULT, why, rid)
    if back > max(opts.antenna_back_m, opts.antenna_back_fraction * peak):
        why = f"the receiver did not come back: {back:.1f} m from the known position after the alarm"
        return _kept("antenna moved", Kind.RECEIVER_FAULT, why, rid)
    if lasted > opts.max_antenna_move_s:
        why = f"the receiver moved for {lasted:.0f} s, longer than an antenna is handled"
        return _kept("antenna moved", Kind.RECEIVER_FAULT, why, rid)
    # every satellite's rate follows the one motion: what is left of each (its tracking loop under the jerk
    # of a hand) is small beside the motion, where one counterfeit satellite's rate would be the motion itself
    inside = (residual.t >= alarm.start_s) & (residual.t <= alarm.end_s)
    r = np.asarray(residual.values, dtype=float)[inside]
    worst = float(np.nanmax(np.abs(r))) if np.isfinite(r).any() else np.nan
    speed = float(np.max(np.linalg.norm(dv, axis=1)))
    if not np.isfinite(worst) or worst > opts.antenna_common_share * speed:
        why = f"a satellite's rate left the receiver's one motion by {worst:.2f} m/s" if np.isfinite(worst) else ""
        return _kept("antenna moved", Kind.RECEIVER_FAULT, why, rid)
    text = (
        f"the receiver moved {peak:.1f} m from its known position and came back within {lasted + 1:.0f} s, every "
        "satellite's rate following that one motion: its antenna handled or knocked (or the known position a "
        "rover's standing point), not spoofing"
    )
    facts = (
        f"moved {peak:.1f} m at up to {speed:.2f} m/s",
        f"back to {back:.2f} m",
        f"every satellite's rate within {worst:.2f} m/s of the motion",
    )
    return Reading("antenna moved", Kind.RECEIVER_FAULT, True, text, facts, rid)


def read_alarm(scene: _Scene, alarm: Alarm, result: DetectorResult) -> list[Reading]:
    """Every signature that applies to this alarm's class, in the order they are preferred."""
    ev = result.evidence
    out: list[Reading] = []
    if ev == Evidence.INERTIAL:
        return [
            read_inertial_shock(scene, alarm),
            read_jammed_fixes(scene, alarm),
            read_glitch(scene, alarm.start_s),
        ]
    if ev == Evidence.LOG_CLOCK:
        return [read_time_fault(scene, alarm, rid) for rid in scene.receivers_of(alarm)]
    if ev in (Evidence.RAW_MEASUREMENT, Evidence.KNOWN_STATION, Evidence.RECEIVER) and len(alarm.satellites) == 1:
        out.append(read_reflection(scene, alarm, result))
    if ev == Evidence.KNOWN_STATION and result.name in (RANGE_RATE, RANGE_RATE_TTEST):
        out.append(read_antenna_moved(scene, alarm))
    if ev == Evidence.RECEIVER and alarm.satellites and result.name != RECEIVER_EVIDENCE:
        out += [read_never_used(scene, alarm, rid) for rid in scene.receivers_of(alarm)]
    if result.name in INDICATOR_DETECTORS:
        for rid in scene.receivers_of(alarm):
            w = scene.window(alarm, rid)
            if w.fixes == 0:
                continue
            marks = spoofer_marks(w, scene.opts)
            out += [
                read_convergence(scene, alarm, w, marks),
                read_held_fix(scene, alarm, w, marks),
                read_mode_switch(scene, alarm, w, marks),
                *([read_skipped_fix(scene, alarm, w, marks)] if result.name == GNSS_CONSISTENCY else []),
                read_interference(scene, alarm, w, marks),
                read_degradation(scene, alarm, w, marks, result.name == GNSS_CONSISTENCY),
            ]
    if ev in (Evidence.GNSS_ONLY, Evidence.RECEIVER):
        out.append(read_glitch(scene, alarm.start_s))
    return out


def incident_alarms(results: Sequence[DetectorResult], incident: Incident) -> list[tuple[Alarm, DetectorResult]]:
    """The counted alarms that make an incident (each is one of its evidence intervals)."""
    spans = set(incident.spans)
    return [
        (a, r)
        for r in results
        if r.is_detector and r.ran and not r.advisory and r.name in incident.detectors
        for a in r.alarms
        if (r.evidence, a.start_s, a.end_s) in spans
    ]


@dataclass(frozen=True)
class Weighed:
    """The natural causes weighed for one incident."""

    explanations: tuple[Explanation, ...]
    explained_spans: tuple[Span, ...]
    ruled_out: tuple[str, ...]  # causes looked at and refused, with why
    # over the whole incident, per receiver: what the receiver says drowned its signals, and a spoofer's marks
    interference: tuple[str, ...] = ()
    spoofer_marks: tuple[SpooferMark, ...] = ()
    # intervals accounted for from their start up to a time only, not beyond
    partly_explained: tuple[tuple[Span, float], ...] = ()

    @property
    def strong_marks(self) -> tuple[SpooferMark, ...]:
        """The marks a headline names (`weighed_marks`)."""
        return tuple(m for m in self.spoofer_marks if m.strong)


def explain(
    table: EpochTable,
    results: Sequence[DetectorResult],
    incident: Incident,
    opts: ExplanationOptions | None = None,
    scene: _Scene | None = None,
) -> Weighed:
    """The natural explanations of an incident's alarms, and the evidence intervals they account for (an
    interval counts as explained when every alarm behind it is)."""
    scene = scene or _Scene(table, results, opts or ExplanationOptions())
    scene.span = (incident.start_s, incident.end_s)
    scene.satellites = incident.satellites
    held: dict[tuple[str, str | None], list[tuple[Reading, str]]] = {}
    refused: dict[str, str] = {}
    # how far into each interval every alarm behind it is accounted for (its end: all of it)
    reach: dict[Span, float] = {}
    for alarm, result in incident_alarms(results, incident):
        assert result.evidence is not None
        key = (result.evidence, alarm.start_s, alarm.end_s)
        readings = read_alarm(scene, alarm, result)
        good = next((rd for rd in readings if rd.held and rd.until_s is None), None)
        good = good or next((rd for rd in readings if rd.held), None)
        upto = float("-inf") if good is None else alarm.end_s if good.until_s is None else good.until_s
        reach[key] = min(reach.get(key, float("inf")), upto)
        if good is not None:
            held.setdefault((good.cause, good.receiver_id), []).append((good, result.name))
        for rd in readings:
            if not rd.held and rd.text and rd.cause not in refused:
                refused[rd.cause] = f"{rd.cause}: {rd.text}"
    explanations = tuple(
        Explanation(
            cause,
            items[0][0].kind,
            items[0][0].text if len(items) == 1 else f"{items[0][0].text} (and {len(items) - 1} more alarm(s) alike)",
            max((rd.facts for rd, _ in items), key=len),
            tuple(sorted({name for _, name in items})),
            rid,
        )
        for (cause, rid), items in held.items()
    )
    held_causes = {e.cause for e in explanations}
    ruled_out = tuple(text for cause, text in refused.items() if cause not in held_causes)
    interference: list[str] = []
    marks: list[SpooferMark] = []
    for rid in incident.receivers or tuple(table.receivers()):
        named = (lambda x, r=rid: f"{r}: {x}") if len(table.receivers()) > 1 else (lambda x: x)
        w = scene.incident_window(rid)
        interference += [named(x) for x in receiver_interference_signs(w, scene.opts.interference_z)]
        if w.fixes:
            marks += [m._replace(text=named(m.text)) for m in weighed_marks(w, scene.opts)]
    # the coasts' departure intervals (no alarm behind them): GNSS agreed with the coasted INS until its
    # departure. Where the jammed receiver's noise accounts for the inertial alarms, a departure that began
    # under the jamming is that noise (the coast weighs GNSS with its clean noise), and the interval counts
    # from the first inertial alarm no cause accounts for (the takeover); a departure that began elsewhere
    # counts from there
    jammed = [(k, r) for k, r in reach.items() if k[0] == Evidence.INERTIAL and r > k[1]]
    if jammed and any(rd.cause == JAMMED for items in held.values() for rd, _ in items):
        inertial = [(k, r) for k, r in reach.items() if k[0] == Evidence.INERTIAL]
        first_open = min((max(r, k[1]) for k, r in inertial if r < k[2]), default=float("inf"))
        under = [(k[1], r) for k, r in jammed] + [
            (a.start_s, a.end_s) for r in results if r.evidence == Evidence.INTERFERENCE and r.ran for a in r.alarms
        ]
        for sp in incident.spans:
            if sp[0] != Evidence.INERTIAL or sp in reach:
                continue
            departed = [d for d in scene.departures_s if sp[1] - DEPARTURE_LEAD_S <= d <= sp[2]]
            elsewhere = [d for d in departed if not any(a <= d <= b for a, b in under)]
            upto = min([*elsewhere, first_open, sp[2]])
            if upto > sp[1]:
                reach[sp] = upto
    # a glitch's departure interval (the coast's, no alarm behind it) is the glitch too
    if any(rd.cause == "glitch" for items in held.values() for rd, _ in items):
        for sp in incident.spans:
            if sp[0] == Evidence.INERTIAL and sp not in reach and read_glitch(scene, sp[1]).held:
                reach[sp] = sp[2]
    spans = tuple(sorted(k for k, r in reach.items() if r >= k[2]))
    partly = tuple(sorted((k, r) for k, r in reach.items() if k[1] < r < k[2]))
    return Weighed(explanations, spans, ruled_out, tuple(interference), tuple(marks), partly)


def scene_of(
    table: EpochTable,
    results: Sequence[DetectorResult],
    opts: ExplanationOptions | None = None,
    departures_s: Sequence[float] = (),
    excursions: Sequence[Excursion] = (),
) -> _Scene:
    """What `explain` reads, shared by the incidents of one log (each receiver's arrays are made once);
    `departures_s`: where the reconstruction stage's coasts confirmed GNSS departing from the INS,
    `excursions`: those that came back."""
    opts = opts or ExplanationOptions()
    return _Scene(table, results, opts, departures_s=tuple(departures_s), excursions=tuple(excursions))
