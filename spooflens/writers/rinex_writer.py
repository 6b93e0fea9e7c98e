"""An EpochTable's raw observations as RINEX 3.04: one observation file per receiver and one navigation
file (GPS, or mixed with Galileo) with the broadcast records behind its satellite states, in one
directory.

This is how a simulated raw log reaches tools that speak RINEX (RTKLIB, gnss_lib_py, teqc) and how
the RINEX reader is checked against a log whose truth is known. RINEX holds observations only:
IMU samples, fixes and truth are not written (the caller is told). Epochs are on GPS time; the
observation types are C1C, L1C, D1C and S1C (pseudorange, carrier phase, Doppler, C/N0), each
written as F14.3, so values keep 1 mm, 0.001 cycle, 0.001 Hz. The MARKER NAME is the receiver id, so
a round trip keeps it.

A synthetic constellation's records are valid at any time (no perturbations); a navigation file
is read by others with a +-2 h validity, so each is re-issued every two hours over the log's span,
with the mean anomaly, node, inclination and clock carried to the new reference time.
"""

from __future__ import annotations

import re
import shutil
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from readers.rinex import GPS_EPOCH
from spooflens.epoch_table import EpochTable
from spooflens.errors import WriterError
from spooflens.geodesy import geodetic_to_ecef
from spooflens.gnss.ephemeris import GM_GALILEO, GM_GPS, OMEGA_E_GPS, SECONDS_PER_WEEK, GpsEphemerides

WRITTEN_SYSTEMS = ("G", "E")  # the navigation records this writer lays out (BeiDou's are not written)
GALILEO_INAV_E5B_CLOCK = 0b1000000101  # RINEX data sources: I/NAV E1-B and E5b, af0-af2 for E5b/E1
OBS_TYPES = (("C1C", "pseudorange_m"), ("L1C", "carrier_phase_cycles"), ("D1C", "doppler_hz"), ("S1C", "cn0_dbhz"))
REISSUE_S = 7200.0


def _label(text: str, label: str) -> str:
    return f"{text:<60.60}{label}\n"


def _program_line() -> str:
    return _label(
        f"{'spooflens':<20}{'spooflens':<20}{datetime.now(UTC).strftime('%Y%m%d %H%M%S UTC'):<20}",
        "PGM / RUN BY / DATE",
    )


def _calendar(gps_s: float) -> datetime:
    return GPS_EPOCH + timedelta(seconds=round(gps_s, 7))


def _header(receiver_id: str, systems: list[str], first_gps_s: float, xyz: np.ndarray) -> str:
    t = _calendar(first_gps_s)
    lines = [
        _label(
            f"{3.04:9.2f}{'':11}{'OBSERVATION DATA':<20}{'M' if len(systems) > 1 else systems[0]:<20}",
            "RINEX VERSION / TYPE",
        ),
        _program_line(),
        _label(receiver_id, "MARKER NAME"),
        _label("NON_GEODETIC", "MARKER TYPE"),
        _label(f"{'unknown':<20}{'unknown':<40}", "OBSERVER / AGENCY"),
        _label(f"{'':<20}{'spooflens':<20}{'':<20}", "REC # / TYPE / VERS"),
        _label(f"{'':<20}{'':<20}", "ANT # / TYPE"),
        _label("".join(f"{v:14.4f}" for v in xyz), "APPROX POSITION XYZ"),
        _label("".join(f"{0.0:14.4f}" for _ in range(3)), "ANTENNA: DELTA H/E/N"),
    ]
    for sys in systems:
        lines.append(
            _label(f"{sys}  {len(OBS_TYPES):3d}" + "".join(f" {code}" for code, _ in OBS_TYPES), "SYS / # / OBS TYPES")
        )
    for sys in systems:
        lines.append(_label(f"{sys} L1C", "SYS / PHASE SHIFT"))
    lines.append(
        _label(
            f"{t.year:6d}{t.month:6d}{t.day:6d}{t.hour:6d}{t.minute:6d}{t.second + t.microsecond / 1e6:13.7f}{'':5}GPS",
            "TIME OF FIRST OBS",
        )
    )
    lines.append(_label("", "END OF HEADER"))
    return "".join(lines)


def _field(v: float) -> str:
    """F14.3 plus blank LLI and signal-strength flags; blank for a missing value (RINEX's convention)."""
    return f"{v:14.3f}  " if np.isfinite(v) and abs(v) < 1e10 else " " * 16


def _body(obs: pd.DataFrame, gps_s: np.ndarray) -> str:
    out: list[str] = []
    values = np.column_stack([obs[col].to_numpy(float) for _, col in OBS_TYPES])
    sv = obs["sv_id"].astype(str).to_numpy()
    starts = np.flatnonzero(np.r_[True, np.diff(gps_s) != 0])
    ends = np.r_[starts[1:], len(gps_s)]
    for a, b in zip(starts, ends, strict=True):
        t = _calendar(float(gps_s[a]))
        sec = t.second + t.microsecond / 1e6
        out.append(f"> {t.year:4d} {t.month:02d} {t.day:02d} {t.hour:02d} {t.minute:02d}{sec:11.7f}  0{b - a:3d}\n")
        for k in range(a, b):
            out.append(f"{sv[k]:<3}" + "".join(_field(v) for v in values[k]).rstrip() + "\n")
    return "".join(out)


def _d19(v: float) -> str:
    """A navigation field as RINEX writes it: D19.12."""
    return f"{v:19.12E}".replace("E", "D")


def _nav_record(r: dict[str, Any]) -> str:
    t = _calendar(float(r["toc_s"]))
    fit = 4.0 if np.isinf(r["max_age_s"]) else 2 * float(r["max_age_s"]) / 3600.0
    galileo = str(r["sv_id"]).startswith("E")
    rows = [
        (r["iode"], r["crs"], r["delta_n"], r["m0"]),
        (r["cuc"], r["e"], r["cus"], r["sqrt_a"]),
        (r["toe_sow"], r["cic"], r["omega0"], r["cis"]),
        (r["i0"], r["crc"], r["omega"], r["omega_dot"]),
        # Galileo (RINEX 3.04 A8): data sources I/NAV E1-B + E5b, clock for E5b/E1; SISA, health, the
        # BGDs (E1/E5a not kept: written as E1/E5b's); GPS: codes on L2, URA, health, TGD, IODC
        (r["idot"], float(GALILEO_INAV_E5B_CLOCK) if galileo else 0.0, r["week"], 0.0),
        (3.12, r["health"], r["tgd"], r["tgd"]) if galileo else (2.0, r["health"], r["tgd"], r["iode"]),
        (r["toe_sow"],) if galileo else (r["toe_sow"], fit),
    ]
    head = (
        f"{r['sv_id']:<3} {t.year:4d} {t.month:02d} {t.day:02d} {t.hour:02d} {t.minute:02d} {t.second:02d}"
        + "".join(_d19(float(r[k])) for k in ("af0", "af1", "af2"))
    )
    return head + "\n" + "".join("    " + "".join(_d19(float(v)) for v in row) + "\n" for row in rows)


def _reissued(eph: GpsEphemerides, first_s: float, last_s: float, svs: set[str]) -> GpsEphemerides:
    """Records of the satellites in `svs` covering [first_s, last_s]: a real file's records as they are,
    a synthetic (never-expiring) record re-issued every two hours with its elements carried along."""
    recs: list[dict[str, Any]] = []
    toe = eph.toe_s
    for i, r in enumerate(eph.records()):
        if str(r["sv_id"]) not in svs:
            continue
        if np.isfinite(r["max_age_s"]):
            if toe[i] + r["max_age_s"] >= first_s and toe[i] - r["max_age_s"] <= last_s:
                recs.append(r)
            continue
        gm = GM_GALILEO if str(r["sv_id"]).startswith("E") else GM_GPS
        n = np.sqrt(gm / r["sqrt_a"] ** 6) + r["delta_n"]
        for new_toe in np.arange(np.floor(first_s / REISSUE_S) * REISSUE_S, last_s + REISSUE_S, REISSUE_S):
            dt = float(new_toe - toe[i])
            week = int(new_toe // SECONDS_PER_WEEK)
            sow = float(new_toe - week * SECONDS_PER_WEEK)
            dtc = float(new_toe - r["toc_s"])
            recs.append(
                r
                | {
                    "week": week,
                    "toe_sow": sow,
                    "toc_s": float(new_toe),
                    "m0": float(np.mod(r["m0"] + n * dt, 2 * np.pi)),
                    "omega0": float(
                        r["omega0"] + (r["omega_dot"] - OMEGA_E_GPS) * dt + OMEGA_E_GPS * (sow - r["toe_sow"])
                    ),
                    "i0": float(r["i0"] + r["idot"] * dt),
                    "af0": float(r["af0"] + r["af1"] * dtc + r["af2"] * dtc**2),
                    "af1": float(r["af1"] + 2 * r["af2"] * dtc),
                    "max_age_s": REISSUE_S,
                }
            )
    if not recs:
        raise WriterError("no broadcast record covers the log's satellites and span")
    return GpsEphemerides.from_records(recs, iono=eph.iono)


def _nav_file(eph: GpsEphemerides) -> str:
    systems = {s[:1] for s in eph.satellites()}
    kind = "G" if systems == {"G"} else "E" if systems == {"E"} else "M"
    head = [
        _label(f"{3.04:9.2f}{'':11}{'N: GNSS NAV DATA':<20}{kind:<20}", "RINEX VERSION / TYPE"),
        _program_line(),
    ]
    if eph.iono is not None:
        head.append(
            _label("GPSA " + "".join(f"{v:12.4E}".replace("E", "D") for v in eph.iono.alpha), "IONOSPHERIC CORR")
        )
        head.append(
            _label("GPSB " + "".join(f"{v:12.4E}".replace("E", "D") for v in eph.iono.beta), "IONOSPHERIC CORR")
        )
    head.append(_label("", "END OF HEADER"))
    return "".join(head) + "".join(_nav_record(r) for r in eph.records())


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9]+", "_", name).strip("_") or "receiver"


def write_rinex(table: EpochTable, path: Path) -> None:
    """Write `table`'s observations as a directory of RINEX 3.04 files (see the module docstring)."""
    path = Path(path)
    obs = table.observations
    if not len(obs):
        raise WriterError(f"{path}: RINEX holds raw observations and this log has none")
    gps = table.gps_seconds(obs["t_s"].to_numpy(float))
    if gps is None:
        raise WriterError(f"{path}: RINEX needs an absolute clock and this log has only relative time")
    if path.exists():
        shutil.rmtree(path) if path.is_dir() else path.unlink()
    path.mkdir(parents=True)
    first, last = float(gps.min()), float(gps.max())
    for rid, rows in obs.groupby("receiver_id", sort=False):
        idx = rows.index.to_numpy()
        order = np.argsort(gps[idx], kind="stable")
        rows, t = rows.iloc[order], gps[idx][order]
        systems = sorted({s[:1] for s in rows["sv_id"].astype(str)}, key=lambda s: (s != "G", s))
        fx = table.fixes[table.fixes["receiver_id"] == rid]
        xyz = (
            geodetic_to_ecef(*(float(fx[c].iloc[0]) for c in ("lat_deg", "lon_deg", "height_m")))
            if len(fx)
            else np.zeros(3)
        )
        text = _header(str(rid), systems, float(t[0]), np.asarray(xyz)) + _body(rows, t)
        (path / f"{_safe(str(rid))}_MO.rnx").write_text(text, encoding="ascii")
    if table.ephemerides is not None:
        svs = {s for s in obs["sv_id"].astype(str) if s[:1] in WRITTEN_SYSTEMS}
        eph = _reissued(table.ephemerides, first, last, svs)
        only_gps = {s[:1] for s in eph.satellites()} == {"G"}
        (path / ("BRDC_GN.rnx" if only_gps else "BRDC_MN.rnx")).write_text(_nav_file(eph), encoding="ascii")
