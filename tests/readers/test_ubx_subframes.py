"""u-blox RXM-SFRBX: GPS LNAV ephemerides decoded from the capture, so RAWX observations get satellite
states and RAIM runs on a capture alone. The capture is built from the real GSI RINEX pair (its
broadcast records encoded field by field from IS-GPS-200, its observations as RAWX)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from paths import REAL, real_log
from ubx_support import capture_from_rinex, lnav_subframes, sfrbx

from readers import read_log
from readers.lnav import LnavDecoder, parity
from readers.rinex import read_rinex_nav_file
from spooflens.cli import main
from spooflens.gnss.ephemeris import GpsEphemerides

PAIR = REAL / "rinex_gsi_pair"
OBS, NAV = PAIR / "07590920.05o", PAIR / "07590920.05n"
WEEK_S = 604_800
# half an LSB of each field's LNAV scale factor (IS-GPS-200 Tables 20-I, 20-III)
QUANTUM = {
    "af0": 2.0**-31, "af1": 2.0**-43, "af2": 2.0**-55, "tgd": 2.0**-31, "crs": 2.0**-5, "crc": 2.0**-5,
    "cuc": 2.0**-29, "cus": 2.0**-29, "cic": 2.0**-29, "cis": 2.0**-29, "e": 2.0**-33, "sqrt_a": 2.0**-19,
    "m0": np.pi * 2.0**-31, "omega0": np.pi * 2.0**-31, "i0": np.pi * 2.0**-31, "omega": np.pi * 2.0**-31,
    "delta_n": np.pi * 2.0**-43, "omega_dot": np.pi * 2.0**-43, "idot": np.pi * 2.0**-43,
}  # fmt: skip


def _need() -> None:
    for path in (OBS, NAV):
        real_log(str(path.relative_to(REAL)))


def _records(eph: GpsEphemerides) -> list[dict[str, float]]:
    return [{k: r[k] for k in ("sv_id", "week", "toe_sow", "toc_s", "health", "iode", *QUANTUM)} for r in eph.records()]


def test_parity_matches_the_icd_written_out() -> None:
    from ubx_support import _parity

    rng = np.random.default_rng(3)
    for d in rng.integers(0, 1 << 24, 300):
        for d29s in (0, 1):
            for d30s in (0, 1):
                assert parity(int(d), d29s, d30s) == _parity(int(d), d29s, d30s)


@pytest.mark.parametrize("restored", [False, True], ids=["as-transmitted", "restored-by-receiver"])
def test_lnav_subframes_decode_to_the_broadcast_records(restored: bool) -> None:
    _need()
    nav = read_rinex_nav_file(NAV).ephemerides
    records = _records(nav)
    decoder = LnavDecoder()
    for rec in records:
        sent = rec["week"] * WEEK_S + rec["toe_sow"] - 60.0
        ref = sent + 1.0
        for words in lnav_subframes(rec, sent, restored):
            decoder.add(sfrbx(int(str(rec["sv_id"])[1:]), words)[6:-2], ref)
    assert decoder.counts["parity failed"] == 0
    got = {(r["sv_id"], r["iode"], r["toe_sow"]): r for r in decoder.records()}
    assert len(got) == len({(r["sv_id"], r["iode"], r["toe_sow"]) for r in records})
    for rec in records:
        out = got[(rec["sv_id"], rec["iode"], rec["toe_sow"])]
        assert out["week"] == rec["week"] and out["health"] == rec["health"]
        assert out["toc_s"] == pytest.approx(rec["toc_s"], abs=8.0)
        for key, q in QUANTUM.items():
            assert float(out[key]) == pytest.approx(rec[key], abs=0.51 * q), key


def test_a_damaged_subframe_fails_parity_and_is_never_an_orbit() -> None:
    _need()
    rec = _records(read_rinex_nav_file(NAV).ephemerides)[0]
    decoder = LnavDecoder()
    ref = rec["week"] * WEEK_S + 3600.0
    for k, words in enumerate(lnav_subframes(rec, ref)):
        if k == 1:
            words[5] ^= 1 << 20  # one bit of M0 flipped
        decoder.add(sfrbx(int(str(rec["sv_id"])[1:]), words)[6:-2], ref)
    assert decoder.counts["parity failed"] == 1 and decoder.records() == []
    # a receiver's wrongly decoded bits in a message the file carried whole: skipped, no damage to the file
    (dropped,) = decoder.dropped("G01")
    assert dropped.reason == "GPS subframes dropped: parity failed" and dropped.action == "skipped"


def _capture(tmp_path: Path, pr_offset: dict[str, float] | None = None) -> Path:
    rinex = read_log(OBS)
    obs = rinex.observations.copy()
    for sv, offset in (pr_offset or {}).items():
        late = (obs["sv_id"] == sv) & (obs["t_s"] >= 1800.0)
        obs.loc[late, "pseudorange_m"] += offset
    # Doppler from the carrier's change (RINEX L grows as the range grows: D = -dL/dt)
    obs = obs.sort_values(["sv_id", "t_s"])
    dl = obs.groupby("sv_id")["carrier_phase_cycles"].diff() / obs.groupby("sv_id")["t_s"].diff()
    obs["doppler_hz"] = -dl.bfill()
    obs = obs.sort_values(["t_s", "sv_id"])
    nav = read_rinex_nav_file(NAV).ephemerides
    iono = (nav.iono.alpha, nav.iono.beta) if nav.iono is not None else None
    path = tmp_path / "gsi_0759.ubx"
    path.write_bytes(capture_from_rinex(obs, rinex.t0_ns / 1e9, _records(nav), iono))
    return path


def test_rawx_capture_with_subframes_has_the_satellite_states_of_the_rinex_pair(tmp_path: Path) -> None:
    _need()
    table = read_log(_capture(tmp_path))
    rinex = read_log(OBS)
    assert any(s.role == "nav" and "RXM-SFRBX" in s.msgtype for s in table.streams)
    assert not any(s.action == "no ephemeris" for s in table.skipped)
    cols = ["sv_x_m", "sv_y_m", "sv_z_m", "sv_clock_bias_m"]
    key = ["t_s", "sv_id"]
    ubx, ref = (o[key + cols].assign(t_s=o["t_s"].round(3)) for o in (table.observations, rinex.observations))
    both = pd.merge(ubx, ref, on=key, suffixes=("_ubx", "_rinex"))
    assert len(both) == len(rinex.observations)
    for c in cols:
        # the same broadcast records: equal up to LNAV quantisation of the RINEX file's printed values
        assert np.nanmax(np.abs(both[f"{c}_ubx"] - both[f"{c}_rinex"])) < 0.05, c
    assert np.isfinite(both["sv_x_m_ubx"]).mean() > 0.95


def test_raim_on_a_capture_alone_names_a_counterfeit_satellite(tmp_path: Path) -> None:
    _need()
    clean, spoofed = tmp_path / "clean", tmp_path / "spoofed"
    clean.mkdir()
    spoofed.mkdir()
    summaries = {}
    for name, folder, offset in (("clean", clean, None), ("spoofed", spoofed, {"G07": 3000.0})):
        log = _capture(folder, offset)
        out = folder / "summary.json"
        code = main(["analyze", str(log), "-o", str(folder / "a.rrd"), "--json", str(out), "--quiet"])
        assert code in (0, 3)
        summaries[name] = json.loads(out.read_text())

    def raim(summary: dict[str, Any]) -> dict[str, Any]:
        return next(d for d in summary["analyses"] if d["name"] == "raim")

    assert raim(summaries["clean"])["ran"] and not raim(summaries["clean"])["alarms"]
    assert not summaries["clean"]["verdict"]["spoofed"]
    spoofed_raim = raim(summaries["spoofed"])
    assert spoofed_raim["alarms"] and all(a["start_s"] >= 1800.0 for a in spoofed_raim["alarms"])
    verdict = summaries["spoofed"]["verdict"]
    assert verdict["spoofed"] and verdict["incidents"][0]["satellites"] == ["G07"]
    assert verdict["incidents"][0]["onset_s"] == pytest.approx(1800.0, abs=1.0)
    assert any("G07 inconsistent by 3 km" in f["text"] for f in verdict["findings"])


def _analyse(folder: Path, counterfeit: list[tuple[float, dict[str, float], float]]) -> dict[str, Any]:
    folder.mkdir()
    rinex = read_log(OBS)
    nav = read_rinex_nav_file(NAV).ephemerides
    records = _records(nav)
    log = folder / "capture.ubx"
    log.write_bytes(capture_from_rinex(rinex.observations, rinex.t0_ns / 1e9, records, None, counterfeit))
    out = folder / "summary.json"
    assert main(["analyze", str(log), "-o", str(folder / "a.rrd"), "--json", str(out), "--quiet"]) in (0, 3)
    summary: dict[str, Any] = json.loads(out.read_text())
    return summary


def _message_detector(summary: dict[str, Any]) -> dict[str, Any]:
    found: dict[str, Any] = next(d for d in summary["analyses"] if d["name"] == "navigation_message")
    return found


def test_navigation_messages_of_a_clean_capture_raise_nothing(tmp_path: Path) -> None:
    _need()
    summary = _analyse(tmp_path / "clean", [])
    nav = _message_detector(summary)
    assert nav["ran"] and not nav["alarms"], nav["reason"]
    assert not summary["verdict"]["spoofed"]


def test_a_counterfeit_navigation_message_is_named(tmp_path: Path) -> None:
    """A spoofer's message for G07 from 1800 s: first an orbit 26 km off with the same issue of data,
    then, for G08, a real orbit sent with its clock an hour off."""
    _need()
    records = _records(read_rinex_nav_file(NAV).ephemerides)
    g07 = next(r for r in records if r["sv_id"] == "G07")
    moved = g07 | {"m0": g07["m0"] + 1e-3}  # 1 mrad along track: 26 km
    g08 = next(r for r in records if r["sv_id"] == "G08")
    summary = _analyse(tmp_path / "fake", [(1800.0, moved, 0.0), (1800.0, g08, 3600.0)])
    nav = _message_detector(summary)
    by_sv = {tuple(a["satellites"]): a for a in nav["alarms"]}
    assert set(by_sv) == {("G07",), ("G08",)}
    assert by_sv[("G07",)]["start_s"] == pytest.approx(1800.0, abs=31.0)
    texts = " ".join(f["text"] for f in summary["verdict"]["findings"])
    assert "G07's broadcast orbit jumped" in texts and "G08: navigation message time off" in texts
    assert summary["verdict"]["spoofed"]


def test_an_orbit_jump_needs_two_records_within_their_fit_span() -> None:
    """A satellite seen again six hours later has a new orbit that the old record cannot predict: no jump."""
    import dataclasses

    from spooflens.detectors.navigation_message import NavigationMessageOptions, _orbit_jumps

    _need()
    nav = read_rinex_nav_file(NAV).ephemerides
    g07 = np.flatnonzero(nav.sv_id == "G07")
    far = [int(i) for i in g07 if abs(float(nav.toe_s[i] - nav.toe_s[g07[0]])) > 4 * 3600]
    if not far:
        pytest.skip("the nav file has no G07 records 4 h apart")
    pair = np.array([int(g07[0]), far[0]])
    eph = dataclasses.replace(nav, received_s=nav.toe_s - 600.0)
    assert not _orbit_jumps(eph, pair, 0.0, 1e12, NavigationMessageOptions()).alarms
