"""Spoofed copies of RINEX observation logs, written as RINEX with every untouched byte kept.

`spooflens inject` changes the observations frame (pseudoranges moved, satellites blocked, C/N0
lowered); this module carries those changes back into the source files. A spoofer delays the whole
signal, so a pseudorange change of `d` metres moves every code observable of that satellite and epoch
(C*, P*) by `d`, every phase observable (L*) by `d / wavelength` cycles at its own carrier, and a change
of pseudorange rate `r` moves every Doppler observable (D*) by `-r / wavelength`. A change of C/N0 (an
interference attack drowning the signals) moves every signal strength (S*) of the satellite by as many
dB, its signal strength indicator (SSI, C/N0 / 6 clipped to 1-9) with it. A phase or Doppler whose
carrier is unknown (GLONASS without its frequency channel) is not edited. A removed row takes the
satellite out of that epoch: its data lines go and the epoch header's count and satellite list are
rewritten (continuation lines included, RINEX 2). An epoch left without satellites is dropped. Fields
keep their exact width (F14.3 + LLI + SSI); everything else is copied byte for byte, the header gaining
one COMMENT line before END OF HEADER.

Rows are matched by (receiver_id, t_s, sv_id) to the lines the reader took them from, through the
same scan (`readers.rinex.scan_obs`), so the two cannot disagree about an epoch's time.
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from readers.rinex import ObsScan, carrier_frequency_hz, find_nav_files, obs_files, parse_fixed, scan_obs
from readers.rinex.text import TextLines
from spooflens.epoch_table import EpochTable
from spooflens.errors import ReaderError, WriterError
from spooflens.gnss.ephemeris import C_MPS

COMMENT = "spoofed copy made by spooflens inject"
IntArray = NDArray[np.int64]
FloatArray = NDArray[np.float64]


@dataclass
class _Plan:
    """What to do to one observation file: scan rows to shift and scan rows to drop."""

    rows: IntArray
    delta_range_m: FloatArray
    delta_rate_mps: FloatArray
    delta_cn0_db: FloatArray
    removed: IntArray
    added: int


def _keyed(df: pd.DataFrame) -> pd.DataFrame:
    """Observation rows keyed by integer ns since the table start (exact, unlike float seconds)."""
    ns = np.round(df["t_s"].to_numpy(dtype=float) * 1e9).astype(np.int64)
    out = pd.DataFrame({"ns": ns, "sv_id": df["sv_id"].to_numpy(dtype=object)})
    for c in ("pseudorange_m", "pseudorange_rate_mps", "doppler_hz", "carrier_freq_hz", "cn0_dbhz"):
        out[c] = df[c].to_numpy(dtype=float) if c in df.columns else np.nan
    return out.drop_duplicates(["ns", "sv_id"])


def _deltas(kept: pd.DataFrame) -> tuple[FloatArray, FloatArray]:
    """Range and range-rate change of each matched row (0 where none).

    A rate missing on either side falls back to the change of the Doppler, which says the same.
    """
    d_range = (kept["pseudorange_m_new"] - kept["pseudorange_m_old"]).to_numpy(dtype=float)
    d_rate = (kept["pseudorange_rate_mps_new"] - kept["pseudorange_rate_mps_old"]).to_numpy(dtype=float)
    d_doppler = (kept["doppler_hz_new"] - kept["doppler_hz_old"]).to_numpy(dtype=float)
    d_rate = np.where(np.isfinite(d_rate), d_rate, -d_doppler * C_MPS / kept["carrier_freq_hz_old"].to_numpy(float))
    return np.where(np.isfinite(d_range), d_range, 0.0), np.where(np.isfinite(d_rate), d_rate, 0.0)


def _scan_rows(scan: ObsScan, t0_ns: int, receiver_id: str, keys: pd.DataFrame) -> IntArray:
    """The scan row of each (ns since the table start, sv_id) key; WriterError for keys not in the file."""
    src = pd.DataFrame(
        {
            "ns": scan.epoch_ns[scan.row_epoch] - t0_ns,
            "sv_id": scan.row_sv.astype(object),
            "row": np.arange(len(scan.row_sv)),
        }
    ).drop_duplicates(["ns", "sv_id"])
    lookup = src.set_index(["ns", "sv_id"])["row"]
    idx = pd.MultiIndex.from_arrays([keys["ns"].to_numpy(), keys["sv_id"].to_numpy()])
    rows = lookup.reindex(idx).to_numpy(dtype=float)
    if np.isnan(rows).any():
        raise WriterError(
            f"{scan.text.path}: {int(np.isnan(rows).sum())} observation rows of receiver {receiver_id!r} are not "
            "in this file (was the table read from it?)"
        )
    return rows.astype(np.int64)


def _plan(scan: ObsScan, table: EpochTable, spoofed: pd.DataFrame, receiver_id: str) -> _Plan:
    """Match the table's rows of one receiver with the spoofed ones: changed, removed, added."""
    mine = (table.observations["receiver_id"] == receiver_id).to_numpy(dtype=bool)
    old = _keyed(table.observations[mine])
    new = _keyed(spoofed[(spoofed["receiver_id"] == receiver_id).to_numpy(dtype=bool)])
    both = old.merge(new, on=["ns", "sv_id"], how="outer", suffixes=("_old", "_new"), indicator=True)
    kept = both[both["_merge"] == "both"]
    d_range, d_rate = _deltas(kept)
    d_cn0 = (kept["cn0_dbhz_new"] - kept["cn0_dbhz_old"]).to_numpy(dtype=float)
    d_cn0 = np.where(np.isfinite(d_cn0), d_cn0, 0.0)
    changed = (d_range != 0.0) | (d_rate != 0.0) | (d_cn0 != 0.0)
    return _Plan(
        _scan_rows(scan, table.t0_ns, receiver_id, kept[changed]),
        d_range[changed],
        d_rate[changed],
        d_cn0[changed],
        _scan_rows(scan, table.t0_ns, receiver_id, both[both["_merge"] == "left_only"]),
        int((both["_merge"] == "right_only").sum()),
    )


def _frequencies(scan: ObsScan, rows: IntArray, obs_type: str, system: str) -> FloatArray:
    """Carrier frequency of `obs_type` for each row (GLONASS: per satellite channel)."""
    if system != "R":
        return np.full(len(rows), carrier_frequency_hz(system, obs_type, scan.version))
    glo = scan.header.glonass_k
    return np.array(
        [carrier_frequency_hz("R", obs_type, scan.version, glo.get(sv)) for sv in scan.row_sv[rows].tolist()]
    )


def _shift_fields(scan: ObsScan, buf: NDArray[np.uint8], plan: _Plan) -> None:
    """Add each row's delta to every code, phase and Doppler field of its satellite, in place."""
    text = scan.text
    layout_of = scan.epoch_layout[scan.row_epoch[plan.rows]]
    sys_of = scan.row_sys[plan.rows]
    span = np.arange(14)
    for lay_id, layout in enumerate(scan.layouts):
        for sys_byte in np.unique(sys_of[layout_of == lay_id]).tolist():
            system = chr(sys_byte)
            sel = np.flatnonzero((layout_of == lay_id) & (sys_of == sys_byte))
            rows = plan.rows[sel]
            types = layout.get("*") if scan.version < 3 else layout.get(system)
            for m, obs_type in enumerate(types or ()):
                kind = obs_type[:1]
                if kind in "CP":
                    delta = plan.delta_range_m[sel]
                elif kind in "LD":
                    freq = _frequencies(scan, rows, obs_type, system)
                    sign = 1.0 if kind == "L" else -1.0
                    src = plan.delta_range_m[sel] if kind == "L" else plan.delta_rate_mps[sel]
                    delta = sign * src * freq / C_MPS
                elif kind == "S":
                    delta = plan.delta_cn0_db[sel]
                else:
                    continue
                line, col = scan.field_at(rows, m)
                values, blank, bad = parse_fixed(text.field(line, col, 14))
                ok = ~blank & ~bad & (values != 0.0) & np.isfinite(delta) & (delta != 0.0)
                ok &= col + 14 <= text.lens[line]
                if not ok.any():
                    continue
                new = np.char.mod("%14.3f", values[ok] + delta[ok])
                if (np.char.str_len(new) != 14).any():
                    raise WriterError(f"{text.path}: a shifted {obs_type} no longer fits its F14.3 field")
                chars = np.frombuffer(new.astype("S14").tobytes(), dtype=np.uint8).reshape(-1, 14)
                pos = (text.starts[line[ok]] + col[ok])[:, None] + span
                buf[pos] = chars
                if kind == "S":
                    _signal_strength_indicator(text, buf, line[ok], col[ok], values[ok] + delta[ok])


def _signal_strength_indicator(
    text: TextLines, buf: NDArray[np.uint8], line: IntArray, col: IntArray, cn0: FloatArray
) -> None:
    """The SSI digit after a signal strength field, where the file has one, from its new value (RINEX:
    1 minimum ... 9 maximum; C/N0 / 6 as receivers map dB-Hz)."""
    at = text.starts[line] + col + 15
    inside = col + 16 <= text.lens[line]
    digit = np.clip(np.floor(cn0 / 6.0), 1, 9).astype(np.uint8) + ord("0")
    has = inside & (buf[np.where(inside, at, 0)] >= ord("1")) & (buf[np.where(inside, at, 0)] <= ord("9"))
    buf[at[has]] = digit[has]


def _epoch_blocks(scan: ObsScan, removed: IntArray) -> tuple[dict[int, list[bytes]], set[int]]:
    """New epoch header lines (by first line index) and lines to delete, for satellites taken out."""
    text = scan.text
    replace: dict[int, list[bytes]] = {}
    delete: set[int] = set()
    by_epoch: dict[int, set[int]] = {}
    for r in removed.tolist():
        by_epoch.setdefault(int(scan.row_epoch[r]), set()).add(int(scan.row_slot[r]))
    for e, slots in by_epoch.items():
        first = int(scan.epoch_line[e])
        n_hdr = int(scan.epoch_header_lines[e])
        head = [text.line(first + k) for k in range(n_hdr)]
        lo, hi = np.searchsorted(scan.row_epoch, [e, e + 1])  # rows are in file (epoch) order
        rows = np.arange(lo, hi)
        eol = int(text.starts[first]) + int(text.lens[first])
        ending = b"\r" if text.data[eol : eol + 1] == b"\r" else b""
        if scan.version < 3:
            nsat = int(head[0][29:32])
            tokens = [head[k // 12][32 + 3 * (k % 12) : 35 + 3 * (k % 12)].ljust(3) for k in range(nsat)]
            lps = int(scan.row_nlines[rows[0]])
            data0 = first + n_hdr
            sat_lines = {k: range(data0 + k * lps, data0 + (k + 1) * lps) for k in range(nsat)}
        else:
            nsat = int(head[0][32:35])
            tokens = []
            sat_lines = {int(scan.row_slot[r]): range(int(scan.row_line[r]), int(scan.row_line[r]) + 1) for r in rows}
        keep = [k for k in (range(nsat) if scan.version < 3 else sat_lines) if k not in slots]
        for k in slots:
            delete.update(sat_lines[k])
        if not keep:
            delete.update(range(first, first + n_hdr))
            if scan.version >= 3:  # lines of unreadable satellites would be orphans
                nxt = first + 1
                while nxt < len(text) and not text.line(nxt).startswith(">"):
                    delete.add(nxt)
                    nxt += 1
            continue
        if scan.version < 3:
            kept = [tokens[k] for k in keep]
            sats = "".join(kept[:12])
            line0 = head[0][:29] + f"{len(kept):3d}" + (sats.ljust(36) + head[0][68:] if len(head[0]) > 68 else sats)
            new = [line0] + [" " * 32 + "".join(kept[i : i + 12]) for i in range(12, len(kept), 12)]
        else:
            new = [head[0][:32] + f"{len(keep):3d}" + head[0][35:]]
        replace[first] = [ln.encode("latin-1") + ending for ln in new]
        delete.update(range(first + 1, first + n_hdr))
    return replace, delete


def _rewrite_file(src: Path, dst: Path, scan: ObsScan, plan: _Plan) -> None:
    text = scan.text
    out = bytearray(text.data)
    buf = np.frombuffer(out, dtype=np.uint8)
    if len(plan.rows):
        _shift_fields(scan, buf, plan)
    replace, delete = _epoch_blocks(scan, plan.removed)
    lines = bytes(out).split(b"\n")
    end = scan.header.end_line
    has_comment = any(COMMENT in text.line(i) for i in range(end))
    ending = b"\r" if lines[end].endswith(b"\r") else b""
    comment = [] if has_comment else [f"{COMMENT:<60}COMMENT".encode("latin-1") + ending]
    if not replace and not delete:
        body = [*lines[:end], *comment, *lines[end:]]
    else:
        body = [*lines[:end], *comment]
        for i in range(end, len(lines)):
            if i in replace:
                body.extend(replace[i])
            elif i not in delete:
                body.append(lines[i])
    try:
        dst.write_bytes(b"\n".join(body))
    except OSError as err:
        raise WriterError(f"{dst}: cannot write: {err.strerror or err}") from err


def _copy_nav_beside(src: Path, dst: Path) -> str:
    """Copy the source's navigation file next to a single-file copy, named so the reader finds it."""
    try:
        navs = find_nav_files(src)
    except ReaderError:
        navs = []
    if len(navs) != 1 or len(dst.suffix) < 2 or dst.suffix[-1] not in "oO":
        return "; navigation file not copied (read the copy with --topic nav=FILE)" if navs else ""
    target = dst.with_suffix(dst.suffix[:-1] + ("n" if dst.suffix[-1] == "o" else "N"))
    if target.resolve() == navs[0].resolve():
        return ""
    if not target.exists():
        shutil.copyfile(navs[0], target)
    return f"; navigation file beside it as {target.name}"


def rewrite_rinex(src: Path, dst: Path, table: EpochTable, spoofed_obs: pd.DataFrame) -> str:
    """Write a spoofed copy of the RINEX log `src` (file or directory) to `dst`; return a one-line note.

    `table` is what the reader made of `src`; `spoofed_obs` its observations frame after an attack
    (rows removed, pseudorange / rate / phase / Doppler values changed).
    """
    src, dst = Path(src), Path(dst)
    if dst.resolve() == src.resolve():
        raise WriterError(f"{dst}: the spoofed copy must not overwrite its source")
    try:
        files = obs_files(src)
    except ReaderError as err:
        raise WriterError(f"{src}: cannot rewrite as RINEX: {err.problem}") from err
    unknown = {str(r) for r in spoofed_obs["receiver_id"].unique()} - {rid for _, rid in files}
    if unknown:
        raise WriterError(f"{src}: receivers {sorted(unknown)} are not in this RINEX log")
    if src.is_dir():
        if dst.is_dir():
            shutil.rmtree(dst)
        elif dst.exists():
            dst.unlink()
        dst.mkdir(parents=True)
        for p in sorted(src.iterdir()):
            if p.is_file():
                shutil.copyfile(p, dst / p.name)
    changed = removed = added = 0
    for path, rid in files:
        scan = scan_obs(path)
        plan = _plan(scan, table, spoofed_obs, rid)
        target = dst / path.name if src.is_dir() else dst
        _rewrite_file(path, target, scan, plan)
        changed, removed, added = changed + len(plan.rows), removed + len(plan.removed), added + plan.added
    note = f"{changed:,} observations changed, {removed:,} removed in {len(files)} file{'s' * (len(files) != 1)}"
    if added:
        note += f" ({added:,} added rows not written: RINEX copies only change or remove satellites)"
    return note + ("" if src.is_dir() else _copy_nav_beside(src, dst))


def rewrite_rinex_log(src: Path, dst: Path, table: EpochTable, spoofed: EpochTable, velocities: bool) -> str:
    """`inject`'s entry point (the common rewrite signature): RINEX keeps only observations."""
    return rewrite_rinex(src, dst, table, spoofed.observations)
