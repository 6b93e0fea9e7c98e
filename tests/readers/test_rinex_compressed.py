"""RINEX read as shipped: gzip, zip (one file or several), Hatanaka Compact RINEX (.crx, .crx.gz, .YYd.Z),
each against the same data read plain; a cut archive keeps what came before the cut; an absurd size
is refused in one line."""

from __future__ import annotations

import gzip
import lzma
import zipfile
from pathlib import Path

import hatanaka
import numpy as np
import pytest
from paths import real_log

from readers import read_log, sniff_format
from readers.rinex import packaging
from spooflens.cli import main
from spooflens.errors import ReaderError

GEORINEX = "corpus/georinex"


def _same_observations(a_path: Path, b_path: Path) -> None:
    a, b = read_log(a_path).observations, read_log(b_path).observations
    assert len(a) == len(b) > 0
    cols = ["t_s", "pseudorange_m", "carrier_phase_cycles", "cn0_dbhz"]
    np.testing.assert_array_equal(a["sv_id"], b["sv_id"])
    np.testing.assert_allclose(a[cols].to_numpy(float), b[cols].to_numpy(float), equal_nan=True)


def test_hatanaka_compact_rinex_3(tmp_path: Path) -> None:
    """P433 (PBO, 2019): a .crx as the archive ships it, read like the RINEX that crx2rnx gives."""
    crx = real_log(f"{GEORINEX}/P43300USA_R_20190012056_17M_15S_MO.crx")
    assert sniff_format(crx) == "rinex"
    t = read_log(crx)
    assert t.absolute_iso(0.0).startswith("2019-01-01T20:56") and t.observations["t_s"].nunique() == 70
    assert any(s.action == "unpacked" and "Compact RINEX (Hatanaka)" in s.reason for s in t.skipped)
    plain = tmp_path / "P43300USA_R_20190012056_17M_15S_MO.rnx"
    plain.write_bytes(hatanaka.decompress(crx))
    _same_observations(crx, plain)


def test_gzipped_observations_find_their_gzipped_navigation_file() -> None:
    """CEDA (2018, a Galileo + GLONASS excerpt): `_MO.rnx.gz` beside its day's `_MN.rnx.gz`: the
    Galileo satellites get their states."""
    t = read_log(real_log(f"{GEORINEX}/CEDA00USA_R_20182100000_23H_15S_MO.rnx.gz"))
    galileo = t.observations[t.observations["sv_id"].str.startswith("E")]
    assert len(galileo) > 1000 and galileo["sv_x_m"].notna().mean() > 0.9
    assert any(s.role == "nav" and "CEDA00USA_R_20182100000_01D_MN" in s.stream_id for s in t.streams)


def test_compact_rinex_inside_gzip_a_whole_day() -> None:
    """CEBR (ESA, 2018): a day at 30 s as `.crx.gz`."""
    t = read_log(real_log(f"{GEORINEX}/CEBR00ESP_R_20182000000_01D_30S_MO.crx.gz"))
    assert t.observations["t_s"].nunique() == 2880 and t.duration_s == pytest.approx(86370.0)
    unpacked = [s.reason for s in t.skipped if s.action == "unpacked"]
    assert unpacked == ["read as shipped: Compact RINEX (Hatanaka) inside gzip, unpacked in memory"]


@pytest.mark.parametrize(
    ("name", "marker", "epochs"), [("ab430140.18o.zip", "AB43", 9), ("york0440.zip", "YORK", 2880)]
)
def test_zip_of_one_observation_file(name: str, marker: str, epochs: int) -> None:
    t = read_log(real_log(f"{GEORINEX}/{name}"))
    assert t.observations["receiver_id"].unique().tolist() == [marker]
    assert t.observations["t_s"].nunique() == epochs


def test_zip_of_observations_and_their_navigation_file(tmp_path: Path) -> None:
    """A zip holding the real 14601736.18o and .18n: the observations read, the nav file inside used."""
    obs, nav = real_log(f"{GEORINEX}/14601736.18o"), real_log(f"{GEORINEX}/14601736.18n")
    archive = tmp_path / "day.zip"
    with zipfile.ZipFile(archive, "w", zipfile.ZIP_DEFLATED) as z:
        z.write(nav, nav.name)
        z.write(obs, obs.name)
    t = read_log(archive)
    assert t.source == archive
    assert [s.stream_id for s in t.streams if s.role == "nav"] == ["14601736.18n"]
    plain = read_log(obs)
    np.testing.assert_allclose(t.observations["sv_x_m"], plain.observations["sv_x_m"], equal_nan=True)
    assert t.observations["sv_x_m"].notna().any()
    only_nav = tmp_path / "nav.zip"
    with zipfile.ZipFile(only_nav, "w") as z:
        z.write(nav, nav.name)
        z.writestr("README.txt", "not rinex")
    assert main(["inspect", str(only_nav)]) == 2


def test_rinex_2_hatanaka_inside_unix_compress(tmp_path: Path) -> None:
    """`.18d.Z`: the real RINEX 2.11 file compressed as archives did (Hatanaka, then compress)."""
    obs = real_log(f"{GEORINEX}/14601736.18o")
    packed = tmp_path / "14601736.18d.Z"
    packed.write_bytes(hatanaka.compress(obs, compression="Z"))
    assert packed.read_bytes()[:2] == b"\x1f\x9d"
    _same_observations(packed, obs)


def test_a_gzip_cut_short_keeps_its_epochs_before_the_cut(tmp_path: Path) -> None:
    src = real_log(f"{GEORINEX}/CEDA00USA_R_20182100000_23H_15S_MO.rnx.gz")
    whole = read_log(src)
    cut = tmp_path / "cut_MO.rnx.gz"
    cut.write_bytes(src.read_bytes()[: src.stat().st_size // 2])
    t = read_log(cut)
    assert 0 < len(t.observations) < len(whole.observations)
    assert any(s.action == "lost" and "gzip stream cut short" in s.reason for s in t.skipped)
    assert main(["inspect", str(cut)]) == 3


def test_an_absurd_size_is_refused_in_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    bomb = tmp_path / "bomb.rnx.gz"
    header = real_log(f"{GEORINEX}/14601736.18o").read_bytes()
    bomb.write_bytes(gzip.compress(header + b" " * (3 * 2**20), compresslevel=1))
    monkeypatch.setattr(packaging, "MAX_UNPACKED_BYTES", 2**20)
    with pytest.raises(ReaderError, match=r"unpacks to more than 1 MiB"):
        read_log(bomb)


def test_compact_rinex_inside_xz_is_the_rinex_readers_own(tmp_path: Path) -> None:
    """xz (the packing `readers.compression` shares with the packed-log reader): read in memory by the RINEX
    reader, the packing named, the same observations as the `.crx` itself."""
    crx = real_log(f"{GEORINEX}/P43300USA_R_20190012056_17M_15S_MO.crx")
    packed = tmp_path / "P43300USA_R_20190012056_17M_15S_MO.crx.xz"
    packed.write_bytes(lzma.compress(crx.read_bytes()))
    assert sniff_format(packed) == "rinex"
    t = read_log(packed)
    unpacked = [s.reason for s in t.skipped if s.action == "unpacked"]
    assert unpacked == ["read as shipped: Compact RINEX (Hatanaka) inside xz, unpacked in memory"]
    _same_observations(crx, packed)
