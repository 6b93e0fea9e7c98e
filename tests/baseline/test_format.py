"""The baseline file: versioned JSON defined once, read back exactly, bad files refused in one line."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from baseline_support import px4_like
from paths import ROOT

from spooflens.baseline.format import VERSION, Baseline, BaselineError, dumps, load_baseline, loads, schema_markdown


def test_a_baseline_is_read_back_as_it_was_written(tmp_path: Path) -> None:
    b = px4_like()
    path = tmp_path / "drone.baseline.json"
    path.write_text(dumps(b))
    assert load_baseline(path) == b
    data = json.loads(path.read_text())
    assert data["format"] == "spooflens-baseline" and data["version"] == VERSION
    q = b.indicator("gps", "noise_per_ms")
    assert q is not None and q.n_logs == 4 and abs(q.centre - 95.0) < 5.0 and q.agree is True
    assert b.indicator("gps", "agc") is None and b.indicator("other", "noise_per_ms") is None


def test_the_documented_schema_is_the_definition() -> None:
    """docs/baseline.md's schema is generated from the dataclasses (`python -m spooflens.baseline.format`)."""
    text = (ROOT / "docs" / "baseline.md").read_text()
    section = re.search(r"<!-- schema:start[^>]*-->\n(.*?)<!-- schema:end -->", text, re.S)
    assert section is not None
    assert section.group(1).strip() == schema_markdown().strip()
    for name in ("Baseline", "ReceiverBaseline", "Quantity", "NavigationBaseline", "PairBaseline", "ClockBaseline"):
        assert f"#### `{name}`" in section.group(1)


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("{not json", "not a baseline (malformed JSON"),
        ("[1, 2]", "not a spooflens baseline (no `format` field"),
        ('{"format": "spooflens-summary"}', "not a spooflens baseline (format 'spooflens-summary'"),
        ('{"format": "spooflens-baseline", "version": 2}', "baseline version 2; this spooflens reads version 1"),
    ],
)
def test_what_is_not_a_version_1_baseline_is_refused(text: str, problem: str) -> None:
    with pytest.raises(BaselineError, match=re.escape(problem)) as err:
        loads(text, "x.json")
    assert str(err.value).startswith("x.json: ") and "\n" not in str(err.value)


def _data() -> dict:
    data: dict = json.loads(dumps(px4_like()))
    return data


def test_a_field_of_the_wrong_type_or_missing_or_unknown_is_named() -> None:
    bad = _data()
    bad["receivers"]["gps"]["indicators"]["noise_per_ms"]["centre"] = "high"
    with pytest.raises(
        BaselineError, match=r"x.json.receivers.gps.indicators.noise_per_ms.centre: 'high' is not a number"
    ):
        loads(json.dumps(bad), "x.json")
    bad = _data()
    del bad["logs"]
    with pytest.raises(BaselineError, match=r"x.json: field 'logs' missing"):
        loads(json.dumps(bad), "x.json")
    bad = _data()
    bad["receivers"]["gps"]["colour"] = "red"
    with pytest.raises(BaselineError, match=r"x.json.receivers.gps: unknown field\(s\) colour"):
        loads(json.dumps(bad), "x.json")


def test_files_that_cannot_be_read(tmp_path: Path) -> None:
    with pytest.raises(BaselineError, match="no such baseline file"):
        load_baseline(tmp_path / "none.json")
    with pytest.raises(BaselineError, match="a folder, not a baseline file"):
        load_baseline(tmp_path)
    binary = tmp_path / "x.baseline.json"
    binary.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(BaselineError, match="not UTF-8 text"):
        load_baseline(binary)


def test_nan_is_written_as_null_and_read_back_as_nan() -> None:
    data = _data()
    data["receivers"]["gps"]["indicators"]["noise_per_ms"]["per_log"][0] = None
    b = loads(json.dumps(data), "x.json")
    assert isinstance(b, Baseline)
    q = b.indicator("gps", "noise_per_ms")
    assert q is not None and q.per_log[0] is None and q.n_logs == 3
