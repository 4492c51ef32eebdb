"""The main job's robustness benchmark (issue 30, item 1) end to end at tiny scale: two labs of the
same hidden model with other fills (lab seeds 0 and 1), their diagnoses in one process with one
shared cache, the truths copied only after, one scored row per seed."""
import json
import subprocess
import sys
from pathlib import Path

import pytest

from validation.hidden_effects import generate_cases

ROOT = Path(__file__).resolve().parents[1]


def test_lab_seeds_give_other_fills_of_the_same_lab(tmp_path):
    with pytest.raises(ValueError, match="lab_seed"):
        generate_cases(["rolling"], tmp_path, "tiny", 2, "cpu", 1, lab_seed=-1)


@pytest.mark.slow
def test_two_seeds_at_tiny_scale(tmp_path):
    out = tmp_path / "robust"
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "main_job_robustness.py"), "--seeds", "2",
                           "--scale", "tiny", "--repeats", "3", "--processes", "2", "--out", str(out)],
                          capture_output=True, text=True, timeout=1800)
    assert done.returncode == 0, done.stderr[-2000:]
    summary = json.loads((out / "summary.json").read_text())
    assert [r["seed"] for r in summary["rows"]] == [0, 1] and all(r["finished"] for r in summary["rows"])
    labs = [yaml_text for yaml_text in ((out / "labs" / f"seed_{k:02d}" / "lab_rolling.yaml").read_text() for k in (0, 1))]
    assert labs[0] != labs[1]  # other fills, other readings
    truth = json.loads((out / "labs" / "seed_01" / "truth_rolling.json").read_text())
    assert truth["lab_seed"] == 1
    assert "right for" in done.stdout and (out / "summary.md").read_text().startswith("# The main job over 2 labs")
