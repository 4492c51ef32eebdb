"""benchmarks/timestep_table.py pools time-step calls by fill: paired changes against the smallest step,
and it refuses to pool records that are not the same experiment (another step in seconds, another law)
or that hold one fill twice."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parents[1] / "benchmarks"))
import timestep_table  # noqa: E402


def record(frac: float, fills: list[int], angles: list[float], dt: float | None = None, law: str = "hertz") -> dict:
    return {"case": "spheres", "law": law, "experiment": "drum", "rpm": 45.0, "dt_rayleigh_fraction": frac,
            "dt_s": dt if dt is not None else 1e-4 * frac / 0.2, "fill_indices": fills, "angles_deg": angles,
            "bulk_densities": None, "wall_s": 1.0}


def write(tmp_path: Path, name: str, lines: list[dict]) -> str:
    path = tmp_path / name
    path.write_text("".join(json.dumps(x) + "\n" for x in lines))
    return str(path)


def test_two_calls_pool_by_fill_and_pair_against_the_smallest_step(tmp_path, capsys):
    first = write(tmp_path, "a.jsonl", [record(0.2, [0, 1], [40.0, 42.0]), record(0.05, [0, 1], [41.0, 42.0]),
                                        {"change_vs_smallest_deg": 9.9}])
    second = write(tmp_path, "b.jsonl", [record(0.2, [2, 3], [44.0, 46.0]), record(0.05, [2], [47.0])])
    assert timestep_table.main([first, second]) == 0
    rows = [r for r in capsys.readouterr().out.splitlines() if r.startswith("| spheres")]
    big, small = rows
    # the larger step: 4 fills, mean 43; paired with the 3 fills run at both steps: -1, 0, -3
    assert "| 0.2 |" in big and "| 4 | 43.00 ± 1.29 |" in big and "-1.33 ± 0.88 (3)" in big
    assert "| 3 | 43.33 ± 1.86 | (reference) |" in small


def test_a_fill_seen_twice_is_refused(tmp_path):
    path = write(tmp_path, "a.jsonl", [record(0.2, [0, 1], [40.0, 42.0]), record(0.2, [1], [43.0])])
    with pytest.raises(SystemExit, match="fill 1 of .* appears twice"):
        timestep_table.main([path])


@pytest.mark.parametrize("other", [dict(dt=2e-4), dict(law="hertz+epsd2")])
def test_calls_of_another_step_or_law_are_not_pooled(tmp_path, other):
    path = write(tmp_path, "a.jsonl", [record(0.2, [0], [40.0]), record(0.2, [1], [41.0], **other)])
    with pytest.raises(SystemExit, match="not the same experiment"):
        timestep_table.main([path])


def test_no_records_is_an_error(tmp_path, capsys):
    assert timestep_table.main([write(tmp_path, "empty.jsonl", [])]) == 2
    assert "no records" in capsys.readouterr().err
