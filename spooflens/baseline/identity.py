"""Which receiver, firmware and IMU a log was recorded with, from what its reader put in the table's
metadata and streams: what a baseline records and what `analyze --baseline` checks a log against.

Readers name things their own way: a u-blox MON-VER `MOD=ZED-F9P`, gpsd's header `Chipset: u-blox
ZED-F9P`, PX4's decoded device id `u-blox 8 (M8) on serial bus 2`, ArduPilot's `detected as u-blox`, a
phone's `Manufacturer: Google Model: Pixel 7`. Two names are the same model when the words of one are
all in the other (`ZED-F9P` and `u-blox ZED-F9P`); names that share no such inclusion are different
models.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from spooflens.epoch_table import EpochTable


@dataclass(frozen=True)
class Identity:
    """What a log says it was recorded with."""

    receivers: dict[str, str | None]  # receiver id -> model (None: not named)
    receiver_firmware: tuple[str, ...]
    firmware: tuple[str, ...]  # the autopilot's, phone's or logger's
    imus: tuple[str, ...]


def _model_of_px4(meta: dict[str, str], rid: str) -> str | None:
    if f"px4.device_id.{rid}" not in meta:
        return None
    for part in meta.get("receiver", "").split("; "):
        name, sep, desc = part.partition(": ")
        if sep and name == rid:
            return desc.split(" on ")[0].strip() or None
    return None


def _log_model(meta: dict[str, str]) -> str | None:
    """The receiver model the log's metadata names, whatever the reader."""
    for key in ("receiver.extensions", "receiver.gpsd_device", "log_header"):
        m = re.search(r"MOD=([A-Za-z0-9\-]+)", meta.get(key, ""))
        if m:
            return m.group(1)
    m = re.search(r"Chipset:\s*([^|,]+)", meta.get("log_header", ""))
    if m and m.group(1).strip():
        return " ".join(m.group(1).split())
    gps = meta.get("receivers", "")  # ArduPilot's GPS lines
    m = re.search(r"(\S+) \d+ HW: (\S+)", gps) or re.search(r"detected as (\S+)", gps)
    if m:
        return m.group(1) + (f" HW {m.group(2)}" if m.lastindex == 2 else "")
    m = re.search(r"Manufacturer: (\S+) Model: (.+)$", meta.get("firmware", ""))
    if m and m.group(2).strip() not in ("", "null"):
        return f"{m.group(1)} {m.group(2).strip()}"
    if meta.get("receiver.hw_version"):
        return f"u-blox HW {meta['receiver.hw_version']}"
    return None


def _receiver_firmware(meta: dict[str, str]) -> tuple[str, ...]:
    out = []
    for key in ("receiver.extensions", "receiver.gpsd_device", "log_header"):
        m = re.search(r"FWVER=([A-Za-z]+ ?[0-9.]+)", meta.get(key, ""))
        if m:
            out.append(m.group(1))
            break
    if meta.get("receiver.sw_version"):
        out.append(meta["receiver.sw_version"])
    m = re.search(r"SW: (.+?)(;|$)", meta.get("receivers", ""))
    if m:
        out.append(m.group(1).strip())
    if not out:
        m = re.search(r"firmware\s+([A-Za-z]*\s?[0-9][0-9.]*)", meta.get("log_header", ""))
        if m:
            out.append(m.group(1).strip())
    return tuple(dict.fromkeys(out))


def identify(table: EpochTable) -> Identity:
    meta = dict(table.metadata)
    log_model = _log_model(meta)
    receivers = {rid: _model_of_px4(meta, rid) or log_model for rid in table.receivers()}
    firmware = tuple(x for x in (meta.get("firmware", "").strip(),) if x)
    imus = tuple(table.imus())
    if meta.get("imu"):
        imus += (meta["imu"],)
    return Identity(receivers, _receiver_firmware(meta), firmware, imus)


def _words(name: str) -> set[str]:
    return set(re.findall(r"[a-z0-9]+", name.lower()))


def same_model(a: str, b: str) -> bool:
    """Whether two receiver-model names name the same model (the words of one all in the other)."""
    wa, wb = _words(a), _words(b)
    return bool(wa and wb) and (wa <= wb or wb <= wa)
