"""The hidden-effect score (benchmarks/score_hidden_effects.py) on a stored paper-scale run: found,
tied and "judged with their own fills' scatter" are read from the diagnosis JSON, never assumed."""
from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).parent.parent
RUN = ROOT / "docs" / "results" / "four_cases_local_noise_h200_2026-11-27"


def _scorer():
    spec = importlib.util.spec_from_file_location("score_hidden_effects", ROOT / "benchmarks" / "score_hidden_effects.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_score_reads_found_tied_and_local_noise_from_the_diagnoses():
    score = _scorer()
    rows = {c: score.score_case(RUN, c) for c in ("base", "rolling", "cohesion", "shape")}
    assert rows["base"]["found"] and rows["base"]["added"] == []
    assert rows["rolling"]["found"] and rows["shape"]["found"]
    coh = rows["cohesion"]
    assert not coh["found"] and coh["tied_not_first"] and coh["top"] == "rolling_resistance"
    assert coh["added"] == ["cohesion"] and coh["local_noise"] == ["drum/45rpm/dynamic_angle"]
    assert all(r["final_within_2_sigma"] for r in rows.values())
    table = score.markdown(list(rows.values()))
    assert "NO, tied with it" in table and "(1 judged with their own fills' scatter)" in table
