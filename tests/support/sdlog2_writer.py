"""PX4 sdlog2 logs (`.px4log`, PX4 firmware 2013-2017) built in tmp_path from the firmware's own FMT
definitions (src/modules/sdlog2/sdlog2_messages.h): the bytes are what that firmware wrote, the values
are a made-up flight.

sdlog2 writes the FMT of each of its messages (not the FMT of FMT: "don't write format of format
message, it's useless"), then VER and PARM, then in each logging loop a TIME message (`StartTime`, us
since boot) followed by whatever was new: no other message carries a time of its own.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pymavlink.DFReader import FORMAT_TO_STRUCT

from spooflens.geodesy import enu_to_geodetic

HEAD = b"\xa3\x95"
G = 9.80665


@dataclass(frozen=True)
class Sdlog2Fmt:
    type: int
    name: str
    format: str
    columns: str

    def _struct(self) -> str:
        return "<" + "".join(FORMAT_TO_STRUCT[c][0] for c in self.format)

    def fmt_message(self) -> bytes:
        body = struct.pack(
            "<BB4s16s64s",
            self.type,
            3 + struct.calcsize(self._struct()),
            self.name.encode(),
            self.format.encode(),
            self.columns.encode(),
        )
        return HEAD + b"\x80" + body

    def message(self, **values: float | str) -> bytes:
        """One message; values in the units the log shows (`L` degrees multiplied back by 1e7, as logged)."""
        out: list[object] = []
        for letter, col in zip(self.format, self.columns.split(","), strict=True):
            code, mult, _ = FORMAT_TO_STRUCT[letter]
            v = values.get(col, 0)
            if isinstance(v, str):
                out.append(v.encode())
            elif mult is not None:
                out.append(round(v / mult))
            else:
                out.append(float(v) if code in "fd" else int(v))
        return HEAD + bytes([self.type]) + struct.pack(self._struct(), *out)


# PX4 master 2016-2017 (PX4/PX4-Autopilot, src/modules/sdlog2/sdlog2_messages.h)
ATT = Sdlog2Fmt(2, "ATT", "fffffffffffff", "qw,qx,qy,qz,Roll,Pitch,Yaw,RollRate,PitchRate,YawRate,GX,GY,GZ")
IMU = Sdlog2Fmt(4, "IMU", "ffffffffffff", "AccX,AccY,AccZ,GyroX,GyroY,GyroZ,MagX,MagY,MagZ,tA,tG,tM")
IMU1 = Sdlog2Fmt(22, "IMU1", "ffffffffffff", "AccX,AccY,AccZ,GyroX,GyroY,GyroZ,MagX,MagY,MagZ,tA,tG,tM")
LPOS = Sdlog2Fmt(6, "LPOS", "ffffffffLLfBBff", "X,Y,Z,Dist,DistR,VX,VY,VZ,RLat,RLon,RAlt,PFlg,GFlg,EPH,EPV")
GPS = Sdlog2Fmt(8, "GPS", "QBffLLfffffBHHH", "GPSTime,Fix,EPH,EPV,Lat,Lon,Alt,VelN,VelE,VelD,Cog,nSat,SNR,N,J")
GPOS = Sdlog2Fmt(16, "GPOS", "LLfffffff", "Lat,Lon,Alt,VelN,VelE,VelD,EPH,EPV,TALT")
TIME = Sdlog2Fmt(129, "TIME", "Q", "StartTime")
VER = Sdlog2Fmt(130, "VER", "NZ", "Arch,FwGit")
PARM = Sdlog2Fmt(131, "PARM", "Nf", "Name,Value")
NEW = (ATT, IMU, IMU1, LPOS, GPS, GPOS, TIME, VER, PARM)

# PX4 of 2013 (thomasgubler/Firmware): ATT in Euler angles only, IMU without temperatures, GPS without
# satellites, SNR, noise and jamming, and its fix type called FixType
ATT_2013 = Sdlog2Fmt(2, "ATT", "ffffff", "Roll,Pitch,Yaw,RollRate,PitchRate,YawRate")
IMU_2013 = Sdlog2Fmt(4, "IMU", "fffffffff", "AccX,AccY,AccZ,GyroX,GyroY,GyroZ,MagX,MagY,MagZ")
GPS_2013 = Sdlog2Fmt(8, "GPS", "QBffLLfffff", "GPSTime,FixType,EPH,EPV,Lat,Lon,Alt,VelN,VelE,VelD,Cog")
GPOS_2013 = Sdlog2Fmt(16, "GPOS", "LLffff", "Lat,Lon,Alt,VelN,VelE,VelD")
OLD = (ATT_2013, IMU_2013, GPS_2013, GPOS_2013, TIME, VER, PARM)

LAT0, LON0, ALT0 = 47.3977419, 8.5455938, 488.0  # AMSL
UTC0_US = 1_464_782_400_000_000  # 2016-06-01 12:00:00 UTC: GPS - UTC = 17 s
BOOT0_US = 30_000_000  # boot time of the first logging loop
SPEED = 10.0  # m/s north
ROLL, PITCH = 0.02, 0.05  # rad
FW_GIT = "b1d2a3f4e5c6d7e8f9a0b1c2d3e4f5a6b7c8d9e0"


@dataclass(frozen=True)
class Flight:
    """What the log says, to compare with what a reader makes of it."""

    path: Path
    boot_us: np.ndarray  # StartTime of each GPS fix's loop
    utc_us: np.ndarray  # GPSTime of each fix (0 before the receiver had the time)
    lat: np.ndarray
    lon: np.ndarray
    alt: np.ndarray
    yaw: float


def write_sdlog2(
    path: Path,
    seconds: float = 60.0,
    imu_hz: int = 100,
    gps_every: int = 20,
    yaw: float = 0.0,
    old: bool = False,
    no_time_fixes: int = 0,
) -> Flight:
    """A straight level flight north at SPEED from (LAT0, LON0, ALT0): one logging loop per IMU sample
    (TIME, IMU, ATT), a GPS fix every `gps_every`-th loop (the first `no_time_fixes` with GPSTime 0, as
    before the receiver had the time) and the autopilot's GPOS/LPOS with it. The IMU is at constant
    velocity: it measures gravity alone, in the FRD body of the attitude (ROLL, PITCH, `yaw`)."""
    fmts = OLD if old else NEW
    att, imu, gps, gpos = (fmts[0], fmts[1], fmts[2 if old else 4], fmts[3 if old else 5])
    out = [f.fmt_message() for f in fmts]
    out.append(VER.message(Arch="PX4FMU_V2", FwGit=FW_GIT))
    for name, value in (("SYS_AUTOSTART", 4001.0), ("MC_ROLL_P", 6.5)):
        out.append(PARM.message(Name=name, Value=value))
    # specific force in FRD body at rest/constant velocity: -R(body<-NED) g_NED
    acc = (G * math.sin(PITCH), -G * math.cos(PITCH) * math.sin(ROLL), -G * math.cos(PITCH) * math.cos(ROLL))
    n_loops = int(seconds * imu_hz)
    boot, utc, lats, lons, alts = [], [], [], [], []
    for k in range(n_loops):
        t_us = BOOT0_US + k * 1_000_000 // imu_hz
        out.append(TIME.message(StartTime=t_us))
        sensor = {"AccX": acc[0], "AccY": acc[1], "AccZ": acc[2], "GyroX": 0.0, "GyroY": 0.0, "GyroZ": 0.0}
        temps = {} if old else {"tA": 41.5, "tG": 41.5, "tM": 30.0}
        out.append(imu.message(**sensor, MagX=0.21, MagY=0.0, MagZ=0.42, **temps))
        if not old:
            out.append(IMU1.message(**sensor, MagX=0.21, MagY=0.0, MagZ=0.42, **temps))
        out.append(att.message(Roll=ROLL, Pitch=PITCH, Yaw=yaw, qw=1.0))
        if k % gps_every:
            continue
        north = SPEED * (t_us - BOOT0_US) / 1e6
        lat, lon, alt = (float(v) for v in enu_to_geodetic(np.array([0.0, north, 0.0]), LAT0, LON0, ALT0))
        i = k // gps_every
        gps_time = 0 if i < no_time_fixes else UTC0_US + (t_us - BOOT0_US)
        vel = {"VelN": SPEED, "VelE": 0.0, "VelD": 0.0}
        fix = {"Lat": lat, "Lon": lon, "Alt": alt, **vel, "EPH": 1.2, "EPV": 2.0}
        extra = {"FixType": 3} if old else {"Fix": 3, "nSat": 12, "SNR": 40, "N": 90, "J": 20}
        out.append(gps.message(GPSTime=gps_time, **fix, Cog=0.0, **extra))
        out.append(gpos.message(**fix))
        if not old:
            out.append(LPOS.message(Y=0.0, X=north, VX=SPEED, RLat=LAT0, RLon=LON0, RAlt=ALT0))
        boot.append(t_us)
        utc.append(gps_time)
        lats.append(lat)
        lons.append(lon)
        alts.append(alt)
    path.write_bytes(b"".join(out))
    return Flight(path, np.array(boot), np.array(utc), np.array(lats), np.array(lons), np.array(alts), yaw)
