"""Logs as shipped: real logs of several formats inside gzip, bzip2, xz, zip and tar read as they read plain;
a cut stream keeps what came before the cut; archives of several logs, paths that leave the folder,
nesting without end and absurd sizes are refused or dropped in one line."""

from __future__ import annotations

import bz2
import gzip
import io
import lzma
import shutil
import tarfile
import zipfile
from pathlib import Path

import numpy as np
import pytest
from paths import SAMPLE_LOGS, real_log
from shared_inputs import read_shared

from readers import packed, read_log, sniff_format
from spooflens.cli import main
from spooflens.epoch_table import HOLDS, EpochTable
from spooflens.errors import ReaderError
from spooflens.pipeline.run import analyze_table


def _same_fixes(a: EpochTable, b: EpochTable) -> None:
    assert len(a.fixes) == len(b.fixes) > 0 and a.format == b.format
    cols = ["t_s", "lat_deg", "lon_deg"]
    np.testing.assert_allclose(a.fixes[cols].to_numpy(float), b.fixes[cols].to_numpy(float), equal_nan=True)
    assert a.t0_ns == b.t0_ns and len(a.imu) == len(b.imu)


@pytest.mark.parametrize(
    ("log", "pack"),
    [
        ("nmea_boats/gpsd_saab-r4.log", "gzip"),
        ("ubx_receivers/gpsd_ublox-zed-f9r.log", "xz"),
        ("corpus/px4-pyulog/sample_log_small.ulg", "bzip2"),
        ("ardupilot_dataflash/amc_backend_log_80k.bin", "zip"),
        ("nmea_boats/gpsd_saab-r4.log", "tar.gz"),
    ],
)
def test_a_packed_real_log_reads_as_it_reads_plain(log: str, pack: str, tmp_path: Path) -> None:
    plain = real_log(log)
    data = plain.read_bytes()
    shipped = tmp_path / f"{plain.name}.{pack}"
    if pack == "gzip":
        shipped.write_bytes(gzip.compress(data))
    elif pack == "xz":
        shipped.write_bytes(lzma.compress(data))
    elif pack == "bzip2":
        shipped.write_bytes(bz2.compress(data))
    elif pack == "zip":
        with zipfile.ZipFile(shipped, "w", zipfile.ZIP_DEFLATED) as z:
            z.write(plain, plain.name)
    else:
        with tarfile.open(shipped, "w:gz") as tar:
            tar.add(plain, plain.name)
    assert sniff_format(shipped) == "packed"
    table = read_log(shipped)
    _same_fixes(table, read_log(plain))
    assert table.source == shipped and pack.split(".")[0] in table.metadata["packing"]
    assert any(s.action == "unpacked" for s in table.skipped)


def test_a_zipped_ros2_bag_folder_gets_the_verdict_of_the_folder(tmp_path: Path) -> None:
    folder = SAMPLE_LOGS / "ground_ros2_sqlite3"
    shipped = Path(shutil.make_archive(str(tmp_path / "bag"), "zip", folder.parent, folder.name))
    verdicts = [analyze_table(read_log(log)).verdict for log in (folder, shipped)]
    assert verdicts[0].incidents == verdicts[1].incidents and verdicts[0].spoofed == verdicts[1].spoofed
    assert verdicts[0].detectors_run == verdicts[1].detectors_run and len(verdicts[0].detectors_run) > 3


def test_a_gzip_cut_short_keeps_what_came_before_the_cut(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    plain = real_log("nmea_boats/signalk_plaka.log")
    whole = gzip.compress(plain.read_bytes())
    cut = tmp_path / "plaka.log.gz"
    cut.write_bytes(whole[: len(whole) // 3])
    table = read_log(cut)
    assert 0 < len(table.fixes) < len(read_shared(plain).fixes)
    assert any(s.action == "lost" and "gzip stream cut short" in s.reason for s in table.skipped)
    assert main(["inspect", str(cut)]) == 3  # read, with a loss


def test_refusals_of_packed_files_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    nmea, bin_log = real_log("nmea_boats/gpsd_saab-r4.log"), real_log("ardupilot_dataflash/amc_backend_log_80k.bin")
    two = tmp_path / "two.zip"
    with zipfile.ZipFile(two, "w") as z:
        z.write(nmea, nmea.name)
        z.write(bin_log, bin_log.name)
    nested = tmp_path / "nested.gz"
    data = nmea.read_bytes()
    for _ in range(4):
        data = gzip.compress(data)
    nested.write_bytes(data)
    empty = tmp_path / "empty.gz"
    empty.write_bytes(gzip.compress(b""))
    expected = {
        two: "zip of 2 separate logs, not one: amc_backend_log_80k.bin (ardupilot), gpsd_saab-r4.log (nmea)",
        nested: "packed 4 times over",
        empty: "gzip stream holds nothing",
    }
    for path, why in expected.items():
        assert main(["inspect", str(path)]) == 2
        err = capsys.readouterr().err
        assert why in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_a_member_whose_path_leaves_the_folder_is_dropped_and_said(tmp_path: Path) -> None:
    nmea = real_log("nmea_boats/gpsd_saab-r4.log")
    archive = tmp_path / "inside" / "slip.zip"
    archive.parent.mkdir()
    with zipfile.ZipFile(archive, "w") as z:
        z.writestr("../../escaped.log", b"$GPGGA,not for outside\r\n")
        z.write(nmea, "logs/r4.log")
    table = read_log(archive)
    assert len(table.fixes) > 0 and table.metadata["packing"] == "zip (logs)"
    assert any(s.action == "lost" and "'../../escaped.log' not unpacked" in s.reason for s in table.skipped)
    assert not list(tmp_path.rglob("escaped.log"))


def test_a_tar_members_link_and_a_name_that_collides_are_dropped_and_said(tmp_path: Path) -> None:
    """A link is never made and a member whose folder an earlier member made a file is not written: each
    listed, and the rest of the archive still unpacked (a collision once stopped the unpacking)."""
    nmea = real_log("nmea_boats/gpsd_saab-r4.log")
    archive = tmp_path / "odd.tar"
    with tarfile.open(archive, "w") as tar:
        link = tarfile.TarInfo("logs/latest.log")
        link.type, link.linkname = tarfile.SYMTYPE, "/etc/passwd"
        tar.addfile(link)
        blocker = tarfile.TarInfo("logs/notes")
        blocker.size = 2
        tar.addfile(blocker, io.BytesIO(b"hi"))
        clash = tarfile.TarInfo("logs/notes/inner.txt")
        clash.size = 2
        tar.addfile(clash, io.BytesIO(b"ho"))
        tar.add(nmea, "logs/r4.log")
    with packed.unpacked(archive) as content:
        reasons = " ".join(content.losses)
        assert "'logs/latest.log' not unpacked (a link or a device: never made)" in reasons
        assert "'logs/notes/inner.txt' not unpacked" in reasons
        assert (content.folder / "logs" / "r4.log").read_bytes() == nmea.read_bytes()
        assert not (content.folder / "logs" / "latest.log").exists()


def test_what_would_unpack_past_the_ceiling_is_refused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    bomb = tmp_path / "zeros.log.gz"
    bomb.write_bytes(gzip.compress(b"\0" * 10_000_000))  # 10 MB from 10 kB
    monkeypatch.setattr(packed, "MAX_UNPACKED_BYTES", 1_000_000)
    with pytest.raises(ReaderError, match=r"gzip unpacks to more than 0.0 GiB .*refused"):
        read_log(bomb)


def test_inject_writes_the_log_inside_a_packed_file_back_unpacked(tmp_path: Path) -> None:
    plain = real_log("nmea_boats/gpsd_saab-r4.log")
    shipped = tmp_path / "r4.log.gz"
    shipped.write_bytes(gzip.compress(plain.read_bytes()))
    out = tmp_path / "spoofed.log"
    assert main(["inject", str(shipped), "--attack", "step:offset=50,axes=n,start=5", "-o", str(out)]) == 0
    assert sniff_format(out) == "nmea"
    before, after = read_log(plain).fixes, read_log(out).fixes
    moved = np.hypot(
        (after["lat_deg"] - before["lat_deg"]) * 111_320.0,
        (after["lon_deg"] - before["lon_deg"]) * 111_320.0 * np.cos(np.radians(before["lat_deg"])),
    )
    attacked = before["t_s"].to_numpy() >= 5.0
    assert np.all(moved[~attacked] < 0.5) and np.all(np.abs(moved[attacked] - 50.0) < 1.0)


def test_a_packed_log_with_nothing_to_judge_says_what_it_holds_and_its_packing(tmp_path: Path) -> None:
    packed_ais = tmp_path / "ais.log.gz"
    packed_ais.write_bytes(gzip.compress(real_log("corpus/gpsd/ais-18-27.log").read_bytes()))
    table = read_log(packed_ais)
    assert not table.streams and table.metadata["packing"] == "gzip (ais.log)"
    assert table.metadata[HOLDS].startswith("AIS messages only (276 VDM")
    assert analyze_table(table).verdict.headline.startswith("NO VERDICT: no GNSS data to judge: AIS messages only")
