"""GPS, Galileo and BeiDou broadcast ephemerides and where each satellite is: IS-GPS-200 (Table 20-IV)
orbit and clock, which the Galileo OS SIS ICD (5.1.1) repeats with its own gravitational constant and the
BDS-SIS-ICD (5.2.4) with CGCS2000's constants, BDT and a tilted frame for its geostationary satellites.

One code path serves real navigation files (`readers.rinex.read_rinex_nav`) and the simulator's
synthetic constellation (`synthetic_constellation`: the same Keplerian elements with the harmonic
corrections set to zero), so a simulated log and a real one meet the same satellite model.

Times are GPS seconds since 1980-01-06 (continuous, no week rollover). A Galileo record's times are
taken on the same scale: GST is steered to GPS time within tens of nanoseconds, and the broadcast
offset between them (GGTO) is left to the receiver's clock unknown per system, which absorbs it.
Positions come out in the ECEF frame of the instant asked for; the rotation of the Earth while the
signal travels is the receiver side's business (`spooflens.gnss.geometry`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spooflens.constants import SPEED_OF_LIGHT_MPS

FloatArray = NDArray[np.float64]

GM_GPS = 3.986005e14  # m^3/s^2, IS-GPS-200's value (not WGS84's 3.986004418e14)
GM_GALILEO = 3.986004418e14  # m^3/s^2, the Galileo ICD's
GM_BEIDOU = 3.986004418e14  # m^3/s^2, BDS-SIS-ICD (CGCS2000)
OMEGA_E_BEIDOU = 7.2921150e-5  # rad/s: CGCS2000's; over a week's toe it moves a node by tens of metres
BDT_OFFSET_S = 14.0  # GPS time - BeiDou time; BDT week 0 began at GPS week 1356
BDT_WEEK_OFFSET = 1356
# BeiDou geostationary satellites: their orbit is given in a frame tilted by 5 degrees (BDS-SIS-ICD 5.2.4.12)
BEIDOU_GEO = frozenset({"C01", "C02", "C03", "C04", "C05", "C59", "C60", "C61", "C62", "C63"})
OMEGA_E_GPS = 7.2921151467e-5  # rad/s
C_MPS = SPEED_OF_LIGHT_MPS
# s/m^0.5, relativistic clock correction constant; Galileo's (from its GM) differs by 1e-7 of a term of
# tens of nanoseconds, so one constant serves both
F_REL = -4.442807633e-10
SECONDS_PER_WEEK = 604800.0
GPS_L1_HZ = 1575.42e6
GPS_L2_HZ = 1227.60e6
CLOCK_GRID_S = 30.0
FIT_INTERVAL_S = 4 * 3600.0  # a broadcast record is used within +-2 h of its toe; we allow the full fit span


@dataclass(frozen=True)
class Klobuchar:
    """Broadcast ionosphere model coefficients (RINEX ION ALPHA / ION BETA)."""

    alpha: tuple[float, float, float, float]
    beta: tuple[float, float, float, float]


@dataclass(frozen=True)
class GpsEphemerides:
    """Broadcast ephemeris records, one entry per record (several per satellite), as parallel arrays:
    GPS LNAV (`sv_id` G..), Galileo I/NAV (E..; `tgd` holds BGD(E1, E5b), `health` the E1-B bits) and
    BeiDou D1/D2 (C..; `tgd` holds TGD1 for B1I; its times on the GPS scale: `week` is the BDT week +
    1356 and `toe_sow` the BDT time of week + 14 s, which may pass the week's end).

    Names follow IS-GPS-200; angles in radians, rates in rad/s, `sqrt_a` in m^0.5. `toe_sow` is the
    time of ephemeris in seconds of GPS week `week`; `toc_s` the clock reference time (GPS seconds).
    `max_age_s` is how far from toe a record may be used (inf for synthetic orbits, which are exact).
    """

    sv_id: NDArray[np.str_]
    week: NDArray[np.int64]
    toe_sow: FloatArray
    toc_s: FloatArray
    af0: FloatArray
    af1: FloatArray
    af2: FloatArray
    tgd: FloatArray
    sqrt_a: FloatArray
    e: FloatArray
    m0: FloatArray
    delta_n: FloatArray
    omega: FloatArray
    i0: FloatArray
    idot: FloatArray
    omega0: FloatArray
    omega_dot: FloatArray
    cuc: FloatArray
    cus: FloatArray
    crc: FloatArray
    crs: FloatArray
    cic: FloatArray
    cis: FloatArray
    health: NDArray[np.int64]
    iode: NDArray[np.int64]
    max_age_s: FloatArray
    # when a receiver decoded the record from the signal (GPS seconds; NaN for a navigation file), and
    # how far the message's own time (its subframes' HOW) was from the receiver's clock then (s)
    received_s: FloatArray
    message_offset_s: FloatArray
    iono: Klobuchar | None = field(default=None, compare=False)

    @classmethod
    def from_records(cls, records: list[dict[str, float | int | str]], iono: Klobuchar | None = None) -> GpsEphemerides:
        """Build from one dict per record (keys: the field names; `max_age_s` defaults to the fit interval,
        `received_s` and `message_offset_s` to NaN)."""
        cols: dict[str, np.ndarray] = {}
        for f in fields(cls):
            if f.name == "iono":
                continue
            default = {"max_age_s": FIT_INTERVAL_S / 2, "received_s": np.nan, "message_offset_s": np.nan}.get(f.name)
            values = [r.get(f.name, default) for r in records]
            if any(v is None for v in values):
                raise ValueError(f"ephemeris record without {f.name!r}")
            dtype = {"sv_id": np.str_, "week": np.int64, "health": np.int64, "iode": np.int64}.get(f.name, np.float64)
            cols[f.name] = np.asarray(values, dtype=dtype)
        order = np.lexsort((cols["week"] * SECONDS_PER_WEEK + cols["toe_sow"], cols["sv_id"]))
        return cls(**{k: v[order] for k, v in cols.items()}, iono=iono)

    @classmethod
    def combined(cls, parts: list[GpsEphemerides]) -> GpsEphemerides:
        """Several sets of records as one (the first ionosphere model given wins; duplicates are harmless:
        the nearest toe wins)."""
        recs = [r for e in parts for r in e.records()]
        return cls.from_records(recs, iono=next((e.iono for e in parts if e.iono), None))

    def records(self) -> list[dict[str, Any]]:
        """One dict per record, the keys of `from_records`: what builds these records again."""
        names = [f.name for f in fields(self) if f.name != "iono"]
        return [{k: getattr(self, k)[i].item() for k in names} for i in range(len(self))]

    def __len__(self) -> int:
        return len(self.sv_id)

    @property
    def toe_s(self) -> FloatArray:
        """Time of ephemeris, GPS seconds."""
        return self.week * SECONDS_PER_WEEK + self.toe_sow

    def satellites(self) -> list[str]:
        return sorted(set(self.sv_id.tolist()))

    def unhealthy_satellites(self) -> list[str]:
        """The satellites every record of which the broadcast flags unhealthy: never used, by choice."""
        healthy = set(self.sv_id[self.health == 0].tolist())
        return sorted(set(self.sv_id.tolist()) - healthy)

    def take(self, idx: NDArray[np.int64]) -> GpsEphemerides:
        return replace(self, **{f.name: getattr(self, f.name)[idx] for f in fields(self) if f.name != "iono"})

    def select(self, sv_id: NDArray[np.str_], t_s: FloatArray) -> NDArray[np.int64]:
        """For each (satellite, GPS time): the healthy record with the nearest toe, or -1 if none is valid."""
        sv_id = np.asarray(sv_id).astype(str)
        t_s = np.asarray(t_s, dtype=float)
        out = np.full(len(sv_id), -1, dtype=np.int64)
        toe = self.toe_s
        for sv in np.unique(sv_id):
            rec = np.flatnonzero((self.sv_id == sv) & (self.health == 0))
            if not len(rec):
                continue
            rows = np.flatnonzero(sv_id == sv)
            # records of one satellite are sorted by toe: the nearest is one of two neighbours
            k = np.clip(np.searchsorted(toe[rec], t_s[rows]), 1, max(len(rec) - 1, 1))
            lo, hi = rec[k - 1], rec[np.minimum(k, len(rec) - 1)]
            best = np.where(np.abs(t_s[rows] - toe[lo]) <= np.abs(t_s[rows] - toe[hi]), lo, hi)
            ok = np.abs(t_s[rows] - toe[best]) <= self.max_age_s[best]
            out[rows[ok]] = best[ok]
        return out


@dataclass(frozen=True)
class SatelliteStates:
    """Satellite position/velocity (ECEF at the instant asked for), clock bias and drift times c."""

    pos_m: FloatArray  # (n, 3), NaN where no valid record
    vel_mps: FloatArray  # (n, 3)
    clock_bias_m: FloatArray  # (n,), includes the relativistic term and L1 group delay (TGD)
    clock_drift_mps: FloatArray  # (n,)
    record: NDArray[np.int64]  # index of the record used, -1 if none

    @property
    def valid(self) -> NDArray[np.bool_]:
        return self.record >= 0

    def columns(self) -> dict[str, FloatArray]:
        """These states as the epoch table's `observations` columns."""
        return {
            "sv_x_m": self.pos_m[:, 0],
            "sv_y_m": self.pos_m[:, 1],
            "sv_z_m": self.pos_m[:, 2],
            "sv_vx_mps": self.vel_mps[:, 0],
            "sv_vy_mps": self.vel_mps[:, 1],
            "sv_vz_mps": self.vel_mps[:, 2],
            "sv_clock_bias_m": self.clock_bias_m,
            "sv_clock_drift_mps": self.clock_drift_mps,
        }


def _kepler(eph: GpsEphemerides, t_s: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Orbit position in ECEF at `t_s` for each record, plus the eccentric anomaly (for the clock)."""
    system = eph.sv_id.astype("U1")
    beidou = system == "C"
    geo = np.isin(eph.sv_id.astype(str), list(BEIDOU_GEO))
    gm = np.where(system == "G", GM_GPS, np.where(beidou, GM_BEIDOU, GM_GALILEO))
    omega_e = np.where(beidou, OMEGA_E_BEIDOU, OMEGA_E_GPS)
    toe_own = eph.toe_sow - np.where(beidou, BDT_OFFSET_S, 0.0)  # the time of week Omega0 is referred to
    a = eph.sqrt_a**2
    tk = t_s - eph.toe_s
    n = np.sqrt(gm / a**3) + eph.delta_n
    m = eph.m0 + n * tk
    ecc_anomaly = m.copy()
    for _ in range(12):  # Newton on E - e sin E = M; e < 0.03 for GPS, converges in a few steps
        ecc_anomaly -= (ecc_anomaly - eph.e * np.sin(ecc_anomaly) - m) / (1.0 - eph.e * np.cos(ecc_anomaly))
    nu = np.arctan2(np.sqrt(1.0 - eph.e**2) * np.sin(ecc_anomaly), np.cos(ecc_anomaly) - eph.e)
    phi = nu + eph.omega
    s2, c2 = np.sin(2 * phi), np.cos(2 * phi)
    u = phi + eph.cus * s2 + eph.cuc * c2
    r = a * (1.0 - eph.e * np.cos(ecc_anomaly)) + eph.crs * s2 + eph.crc * c2
    inc = eph.i0 + eph.cis * s2 + eph.cic * c2 + eph.idot * tk
    # a geostationary BeiDou node does not turn with the Earth here: the frame is rotated below
    node = eph.omega0 + (eph.omega_dot - np.where(geo, 0.0, omega_e)) * tk - omega_e * toe_own
    xp, yp = r * np.cos(u), r * np.sin(u)
    pos = np.stack(
        [
            xp * np.cos(node) - yp * np.cos(inc) * np.sin(node),
            xp * np.sin(node) + yp * np.cos(inc) * np.cos(node),
            yp * np.sin(inc),
        ],
        axis=-1,
    )
    if geo.any():
        pos[geo] = _geo_to_ecef(pos[geo], (omega_e * tk)[geo])
    return pos, ecc_anomaly, n


def _geo_to_ecef(p: FloatArray, earth_angle: FloatArray) -> FloatArray:
    """BDS-SIS-ICD 5.2.4.12: R_Z(Omega_e t_k) R_X(-5 deg) applied to a GEO's position."""
    c, s = np.cos(np.radians(-5.0)), np.sin(np.radians(-5.0))
    x, y, z = p[:, 0], c * p[:, 1] + s * p[:, 2], -s * p[:, 1] + c * p[:, 2]
    ca, sa = np.cos(earth_angle), np.sin(earth_angle)
    return np.stack([ca * x + sa * y, -sa * x + ca * y, z], axis=-1)


def _clock(eph: GpsEphemerides, t_s: FloatArray, ecc_anomaly: FloatArray) -> FloatArray:
    dt = t_s - eph.toc_s
    rel = F_REL * eph.e * eph.sqrt_a * np.sin(ecc_anomaly)
    return eph.af0 + eph.af1 * dt + eph.af2 * dt**2 + rel - eph.tgd


def satellite_states(eph: GpsEphemerides, sv_id: NDArray[np.str_] | list[str], t_s: FloatArray) -> SatelliteStates:
    """Position, velocity and clock of each satellite at GPS time `t_s` (one row per pair).

    Velocity and clock drift are central differences over +-0.5 s: the orbit is smooth enough that
    this is exact to far below a mm/s, and it cannot disagree with the position function.
    """
    sv_id = np.asarray(sv_id).astype(str)
    t_s = np.broadcast_to(np.asarray(t_s, dtype=float), sv_id.shape).copy()
    rec = eph.select(sv_id, t_s)
    n = len(sv_id)
    pos = np.full((n, 3), np.nan)
    vel = np.full((n, 3), np.nan)
    bias = np.full(n, np.nan)
    drift = np.full(n, np.nan)
    ok = rec >= 0
    if ok.any():
        sub = eph.take(rec[ok])
        tt = t_s[ok]
        p, ecc, _ = _kepler(sub, tt)
        h = 0.5
        p_plus, ecc_plus, _ = _kepler(sub, tt + h)
        p_minus, ecc_minus, _ = _kepler(sub, tt - h)
        pos[ok] = p
        vel[ok] = (p_plus - p_minus) / (2 * h)
        bias[ok] = C_MPS * _clock(sub, tt, ecc)
        drift[ok] = C_MPS * (_clock(sub, tt + h, ecc_plus) - _clock(sub, tt - h, ecc_minus)) / (2 * h)
    return SatelliteStates(pos, vel, bias, drift, rec)


def record_positions(eph: GpsEphemerides, rec: NDArray[np.int64], t_s: FloatArray) -> tuple[FloatArray, FloatArray]:
    """ECEF position (m) and clock bias times c (m) of record `rec[i]` at GPS time `t_s[i]`, whatever its
    age or health: for comparing two broadcasts of one satellite."""
    sub = eph.take(np.asarray(rec, dtype=np.int64))
    t = np.asarray(t_s, dtype=float)
    pos, ecc, _ = _kepler(sub, t)
    return pos, C_MPS * _clock(sub, t, ecc)


def synthetic_constellation(
    t_ref_s: float,
    planes: int = 6,
    per_plane: int = 4,
    inclination_deg: float = 55.0,
    semi_major_axis_m: float = 26_559_700.0,
    phasing: int = 1,
    rng: np.random.Generator | None = None,
    system: str = "G",
) -> GpsEphemerides:
    """A Walker constellation (GPS-like 24/6/1 by default; `galileo_constellation` for Galileo's) as
    broadcast records valid at any time, satellites named `system` + number.

    Circular orbits, no perturbations; with `rng`, each satellite gets a small clock offset and drift
    (a few microseconds, 1e-12 s/s) as real ones have, so the receiver must apply the clock model.
    """
    total = planes * per_plane
    week = int(t_ref_s // SECONDS_PER_WEEK)
    toe_sow = t_ref_s - week * SECONDS_PER_WEEK
    recs: list[dict[str, float | int | str]] = []
    for p in range(planes):
        for s in range(per_plane):
            k = p * per_plane + s
            recs.append(
                {
                    "sv_id": f"{system}{k + 1:02d}",
                    "week": week,
                    "toe_sow": toe_sow,
                    "toc_s": t_ref_s,
                    "af0": float(rng.normal(0.0, 5e-6)) if rng is not None else 0.0,
                    "af1": float(rng.normal(0.0, 1e-12)) if rng is not None else 0.0,
                    "af2": 0.0,
                    "tgd": 0.0,
                    "sqrt_a": float(np.sqrt(semi_major_axis_m)),
                    "e": 0.0,
                    "m0": float(np.radians(360.0 * s / per_plane + 360.0 * phasing * p / total)),
                    "delta_n": 0.0,
                    "omega": 0.0,
                    "i0": float(np.radians(inclination_deg)),
                    "idot": 0.0,
                    # broadcast Omega0 is referred to the week start: this puts the node at `360 p / planes`
                    # degrees of ECEF longitude at t_ref
                    "omega0": float(np.radians(360.0 * p / planes) + OMEGA_E_GPS * toe_sow),
                    "omega_dot": 0.0,
                    "cuc": 0.0,
                    "cus": 0.0,
                    "crc": 0.0,
                    "crs": 0.0,
                    "cic": 0.0,
                    "cis": 0.0,
                    "health": 0,
                    "iode": 0,
                    "max_age_s": np.inf,
                }
            )
    return GpsEphemerides.from_records(recs)


def galileo_constellation(t_ref_s: float, rng: np.random.Generator | None = None) -> GpsEphemerides:
    """Galileo's nominal Walker 24/3/1 at 56 degrees and 29,600 km, satellites E01-E24."""
    return synthetic_constellation(t_ref_s, 3, 8, 56.0, 29_600_318.0, 1, rng, "E")


def states_at_transmission(
    eph: GpsEphemerides, sv_id: NDArray[np.str_] | list[str], t_rx_s: FloatArray, pseudorange_m: FloatArray
) -> SatelliteStates:
    """Satellite states at the transmission time a receiver can infer from its own measurements.

    t_tx = t_rx - pseudorange / c - dt_sv(t_tx): the receiver clock bias inside the pseudorange
    cancels the one in the receiver's time tag, so no position is needed (RTKLIB's `satposs`).
    This is how every reader and the simulator fill `sv_x_m` ...: one convention for all logs.
    The clock for that one correction is taken per satellite on a 30 s grid: it changes by
    millimetres in 30 s (picoseconds of t_tx), and it halves the cost of a day of 1 Hz data.
    """
    sv = np.asarray(sv_id).astype(str)
    t_tx = np.asarray(t_rx_s, dtype=float) - np.asarray(pseudorange_m, dtype=float) / C_MPS
    clock = np.zeros(len(sv))
    if len(sv):
        codes, names = np.unique(sv, return_inverse=True)
        grid = np.round(t_tx / CLOCK_GRID_S).astype(np.int64)
        _, first, back = np.unique(grid * len(codes) + names.ravel(), return_index=True, return_inverse=True)
        at = np.asarray(grid[first] * CLOCK_GRID_S, dtype=np.float64)
        clock = satellite_states(eph, sv[first], at).clock_bias_m[back.ravel()]
        edge = np.flatnonzero(~np.isfinite(clock))  # grid point outside the record's validity: ask at t_tx
        if len(edge):
            clock[edge] = satellite_states(eph, sv[edge], t_tx[edge]).clock_bias_m
    return satellite_states(eph, sv, t_tx - np.nan_to_num(clock) / C_MPS)
