"""benchmarks/RESULTS.md is generated from benchmarks/figures.json and the notes (issue 30, item 2):
the shipped file is what the records give, and a record without its command, machine, date or
note is refused by name."""
from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
spec = importlib.util.spec_from_file_location("results_table", ROOT / "benchmarks" / "results_table.py")
results_table = importlib.util.module_from_spec(spec)
spec.loader.exec_module(results_table)


def test_shipped_results_md_is_generated_from_the_records():
    assert results_table.main(["--check"]) == 0
    records = results_table.load_figures()
    text = (ROOT / "benchmarks" / "RESULTS.md").read_text(encoding="utf-8")
    assert len(records) >= 10
    for r in records:  # every current figure in the table, with its note linked
        assert f"**{r['value']}**" in text and f"docs/notes/{r['note']}.md" in text


@pytest.mark.parametrize("field", ["command", "machine", "date", "note"])
def test_a_record_without_its_provenance_is_refused(tmp_path, field):
    doc = json.loads(results_table.FIGURES.read_text(encoding="utf-8"))
    doc["figures"][0][field] = ""
    bad = tmp_path / "figures.json"
    bad.write_text(json.dumps(doc))
    with pytest.raises(SystemExit, match=field):
        results_table.load_figures(bad)


def test_a_record_naming_a_missing_note_is_refused(tmp_path):
    doc = json.loads(results_table.FIGURES.read_text(encoding="utf-8"))
    doc["figures"][0]["note"] = "no_such_note"
    bad = tmp_path / "figures.json"
    bad.write_text(json.dumps(doc))
    with pytest.raises(SystemExit, match="no_such_note"):
        results_table.load_figures(bad)
