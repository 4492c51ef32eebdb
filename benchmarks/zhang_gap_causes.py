"""Causes of the gap between our DEM and the seed paper's EDEM, tested (issue 32, item 2).

    python benchmarks/zhang_gap_causes.py --device cuda --ray local --time-limit 540 --out results/zhang_gap_causes

Our DEM at 40 of the paper's Appendix-A points (``docs/results/reproduce_zhang2023_40pts_h200x4_2026-11-28``)
is less frictional than the paper's EDEM: static angle A RMSE 6.33 deg (bias -2.1), drum angle B30
RMSE 8.21 deg (bias -4.8). This script runs a handful of those points again under named VARIANTS
of the model or protocol and says which variant moves our angle towards EDEM's.

Points (``--rows``, or by default from that folder's ``samples.jsonl``): per angle, the 6 paper rows
with the largest |gap| and the 2 with the smallest (controls); A's rows run in the baffle, B30's in
the drum. Each variant is one batch per experiment: every row x ``--replicates`` worlds in one launch,
each world on its own loose fill (``fill_per_world``; world k of a batch uses fill
``--first-fill + k``, the same in every variant, so two variants are compared on the same fills:
a paired comparison). The model is the reproduction's (``calibration/configs/paper_gravel.yaml``:
the gravel clump mix, hertz + history + rolling ``cdt``), run through the project's experiments
(:func:`calibration.experiments.make_experiment`).

Variants (:data:`VARIANTS`; each a small dict of overrides; the hypothesis it tests):

- ``as_run``: the reproduction's model as it ran, each world on its own fill. Tests nothing; it
  checks that the stored angles (one shared fill) come back within the fill-to-fill noise, and it
  is the baseline of the paired changes.
- ``spheres``: volume-equivalent spheres (one per clump, same volume, mass and number fractions as
  the five clump shapes) instead of clumps. Shape: if the spheres' angles fall far below the
  clumps', shape carries the friction, and our parametric clumps may interlock less than the
  paper's scanned ones (Table 4's fill quality).
- ``gravel_low_fill``: the same five clump shapes filled at the paper's low fill level (Table 2:
  5-8 spheres per clump instead of 22-25). Angularity: fewer, less overlapping spheres make bumpier
  clumps that interlock. Over the 40 points EDEM's static angle follows sliding friction 2.6 x more
  steeply than ours and hardly depends on rolling friction, while ours follows both about equally
  (docs/notes/seed_paper_reproduction.md): our clumps roll where the scanned gravel interlocks.
- ``cdt_liggghts``: LIGGGHTS' cdt rolling resistance (elastic force, lever R*) instead of EDEM's
  (total force, lever R_i ~ 2 R* between equal spheres). Rolling convention: half the lever, so
  this should lower the angles; the size of that drop is the sensitivity to the convention.
- ``epsd2``: LIGGGHTS' elastic-plastic spring rolling resistance instead of a constant torque.
  Rolling convention: a spring holds a static pile that a constant torque lets creep.
- ``dt_half``: half the time step (``dt_rayleigh_fraction`` set so that the step is half the
  recommended one the reproduction used). Time step: an angle that moves with the step is not
  converged (the paper used 4.2e-5 s, ours 3.3e-5 s).
- ``dt_double`` (not in the default list): twice the recommended step. Cost, not the gap (issue 32,
  item 3): clumps step 2.5 x finer than spheres; if the angles do not move at twice the step, the
  reproduction's DEM costs half. Run it with ``--variants as_run dt_half dt_double``.
- ``drum_smooth`` (drum only): the drum shell with 4 x the facets (``sections`` 288 instead of 72).
  Facets give grip: a polygonal shell holds the bed's contact layer better than a round one, so
  a smoother drum should lower B30 if facets matter at all (EDEM's drum is a finer CAD mesh).
- ``short`` (drum only): the drum's "short" preset revolutions (2 discarded + 4 recorded instead
  of the paper's 5 + 10). Protocol: how much the angle depends on the revolutions at all.
- ``long_protocol`` (drum only): 10 discarded + 10 recorded revolutions (the reproduction already
  ran the paper's 5 + 10). Protocol: whether the bed is still changing after 5 revolutions
  (compaction, segregation of the five shapes); a rising angle would mean our protocol is short.
- ``edem_rolling_arm``: rolling ``cdt_body_arm`` (:class:`warpdem.contact.rolling.BodyArmCDT`),
  EDEM's Standard Rolling Friction as its documentation defines it: the lever R_i from the contact
  point to the clump's centre of mass (not the member sphere's centre) and the torque along the
  clump's own unit angular velocity (not the relative one). Rolling convention for multi-sphere
  particles: the outermost point of a member sphere lies |c| + r from the clump's centre of mass,
  against our r (median 1.8 to 4 x r over the members of each of the five shapes, up to 5.4 x), and
  a bed turning with the drum feels a torque that ``cdt`` does not give.

Not in the default list (``--variants`` names them): ``clump_damping_body`` (the clump's contact
damped for the whole-body mass, as in LIGGGHTS and many codes, instead of the mass felt at the
contact point: clump damping).

Output (``--out``): ``runs.jsonl``, one line per (variant, row, experiment, replicate) with the
angle, the paper's EDEM angle, the gap, the stored reproduction angle, the fill, the step and the
batch's timing; ``summary.md`` / ``summary.json``: per experiment and variant, the mean gap to
EDEM's angle on the largest-gap rows and on the controls with its standard error (from the
fill-to-fill scatter), the RMSE, and the change against ``as_run`` on the same fills (paired,
with its standard error), so that a variant that closes the gap shows; then every row's angles.
Running the same command again skips the batches already recorded (``--retry-failed`` runs failed
ones again). ``--time-limit S``: start no batch after S seconds and stop there (a batch still
running is checkpointed every ``--checkpoint-every`` s in ``OUT/checkpoints``: the next call
continues it). ``--plan``: list the batches and their expected GPU time, run nothing.

On several GPUs: ``--ray local`` (a Ray cluster on this machine, one batch per GPU at a time,
through :class:`calibration.executor.RayExecutor`) or ``--ray auto``. ``--scale quick --device cpu``
is a smoke test (sphere materials; no comparison with EDEM).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import platform
import subprocess
import sys
import time
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import warpdem as wd  # noqa: E402
from warpdem import ConfigError  # noqa: E402
from warpdem.json_io import jsonable  # noqa: E402
from warpdem.provenance import json_digest  # noqa: E402

from calibration import campaign as cp  # noqa: E402
from calibration.campaign_records import code_version  # noqa: E402
from calibration.executor import RayExecutor  # noqa: E402
from calibration.materials import BulkMaterial  # noqa: E402
from calibration.experiments import make_experiment  # noqa: E402
from calibration.experiments.checkpoints import BatchCheckpoints, clear_checkpoints  # noqa: E402
from calibration.experiments.common import _run_chunk_on_ray  # noqa: E402
from calibration.materials import BulkMaterial  # noqa: E402
from calibration.reproduction import DEFAULT_CONFIG, PAPER_RESPONSE_BY_EXPERIMENT, paper_points  # noqa: E402

#: the reproduction whose stored angles choose the default rows and are the as_run check
DEFAULT_RESULTS = ROOT / "docs" / "results" / "reproduce_zhang2023_40pts_h200x4_2026-11-28"
EXPERIMENTS = ("baffle", "drum")
ANGLE_LABEL = {"baffle": "A", "drum": "B30"}

#: Each variant: overrides of the reproduction's model or protocol (module docstring). Keys:
#: ``hypothesis`` (one line for the summary), ``experiments`` (where it applies; default both),
#: ``contact_law`` (sub-model names / options replaced in the config's law), ``material``
#: ("volume_equivalent_spheres"), ``dt_factor`` (x the recommended step), ``settings`` (experiment
#: settings), ``sections_factor`` (x the drum's facets), ``revolutions`` ((discarded, recorded)
#: factors of the drum's revolutions, rounded, at least 0 and 1), ``cost`` (GPU time relative to
#: as_run, per experiment: for --plan and --time-limit).
VARIANTS: dict[str, dict[str, Any]] = {
    "as_run": {"hypothesis": "baseline: the reproduction's model; reproduces the stored angles within fill noise"},
    "spheres": {"material": "volume_equivalent_spheres",
                "hypothesis": "shape: volume-equivalent spheres instead of the clumps",
                "cost": {"baffle": 0.15, "drum": 0.15}},
    "gravel_low_fill": {"material": "gravel_low_fill",
                        "hypothesis": "angularity: the paper's low fill level (Table 2: 5-8 spheres per clump) "
                                      "gives bumpier clumps that interlock (EDEM's A follows sliding friction "
                                      "2.6 x more steeply than ours and hardly rolling friction)",
                        "cost": {"baffle": 0.4, "drum": 0.4}},
    "cdt_liggghts": {"contact_law": {"rolling": "cdt_liggghts"},
                     "hypothesis": "rolling convention: LIGGGHTS cdt (elastic force, lever R*)"},
    "epsd2": {"contact_law": {"rolling": "epsd2"},
              "hypothesis": "rolling convention: elastic-plastic spring (LIGGGHTS epsd2)",
              "cost": {"baffle": 1.1, "drum": 1.1}},
    "dt_half": {"dt_factor": 0.5, "hypothesis": "time step: half the recommended step",
                "cost": {"baffle": 2.0, "drum": 2.0}},
    "dt_double": {"dt_multiple": 2.0, "default": False,
                  "hypothesis": "cost (issue 32, item 3): twice the recommended step; clumps step 2.5 x finer than "
                                "spheres, and angles that do not move at 2 x would halve the reproduction's cost",
                  "cost": {"baffle": 0.5, "drum": 0.5}},
    "drum_smooth": {"experiments": ["drum"], "sections_factor": 4,
                    "hypothesis": "facets give grip: drum shell with 4 x the facets",
                    "cost": {"drum": 1.05}},
    "short": {"experiments": ["drum"], "revolutions": [0.4, 0.4],
              "hypothesis": "protocol: the short preset's 2 + 4 drum revolutions",
              "cost": {"drum": 0.45}},
    "long_protocol": {"experiments": ["drum"], "revolutions": [2.0, 1.0],
                      "hypothesis": "protocol: 10 + 10 drum revolutions (steady state after 5?)",
                      "cost": {"drum": 1.35}},
    "edem_rolling_arm": {"contact_law": {"rolling": "cdt_body_arm"},
                         "hypothesis": "rolling convention: EDEM's lever to the clump's centre of mass, "
                                       "its own spin (cdt_body_arm)"},
    "clump_damping_body": {"contact_law": {"clump_damping_mass": "body"}, "default": False,
                           "hypothesis": "clump damping: whole-body mass instead of the mass felt at the contact"},
}
#: the default variants in the order their batches start (the likeliest causes first, so that a
#: run cut short by its time budget has tested those): the shape and EDEM's own rolling convention,
#: then the drum's wall and protocol, the other rolling conventions, the step
DEFAULT_VARIANTS = ["as_run", "spheres", "gravel_low_fill", "edem_rolling_arm", "drum_smooth", "long_protocol",
                    "cdt_liggghts", "epsd2", "dt_half", "short"]
assert set(DEFAULT_VARIANTS) == {k for k, v in VARIANTS.items() if v.get("default", True)}

#: GPU seconds per world of the reproduction's as_run batches on one NVIDIA H200 with 8-13 worlds
#: per GPU (that folder's records: baffle 38 worlds on 3 GPUs in 165 s, drum 35 worlds on 4 GPUs in
#: 408 s); a batch of fewer worlds costs nearly as much as one of 8
GPU_SECONDS_PER_WORLD = {"baffle": 13.0, "drum": 46.6}
MIN_WORLDS_FOR_COST = 8
#: a batch is started only with at least this much of --time-limit left [s]
MIN_START_S = 60.0


# ----------------------------------------------------------------------------- points
@dataclass(frozen=True)
class Row:
    """One paper point in one experiment: row number (1-140), role, our parameter values by name,
    the paper's EDEM angle and the reproduction's stored angle [deg], and its group
    ("largest_gap", "control" or "chosen")."""

    row: int
    role: str
    parameters: dict[str, float]
    paper_deg: float
    stored_deg: float | None
    group: str


def stored_angles(results: Path, points) -> dict[tuple[str, int], float]:
    """The reproduction's angles by (experiment, paper row), matched to the paper's rows by
    their parameter values (``samples.jsonl`` of ``results``)."""
    out: dict[tuple[str, int], float] = {}
    path = Path(results) / "samples.jsonl"
    if not path.exists():
        return out
    exp_of = {f"{r}": e for e, r in (("baffle", "alpha_static"), ("drum", "beta_dynamic"))}
    for line in path.read_text().splitlines():
        if not line.strip():
            continue
        rec = json.loads(line)
        exp = exp_of.get(rec.get("response"))
        if exp is None or rec.get("status") != "ok" or rec.get("angle_deg") is None:
            continue
        x = np.array([float(rec["parameters"][n]) for n in points.parameter_names])
        hit = np.flatnonzero(np.all(np.abs(points.X - x) < 1e-9, axis=1))
        if hit.size == 1:
            out[(exp, int(points.rows[hit[0]]))] = float(rec["angle_deg"])
    return out


def choose_rows(points, stored: Mapping[tuple[str, int], float], experiment: str, rows: Sequence[int] | None,
                top: int, controls: int) -> list[Row]:
    """The rows ``experiment`` runs: ``rows`` as given (group "chosen"), or the ``top`` rows with
    the largest |stored - paper| and the ``controls`` rows with the smallest."""
    j = {"baffle": 0, "drum": 1}[experiment]  # paper_deg columns: alpha_static_deg, beta_dynamic_deg
    index = {int(r): k for k, r in enumerate(points.rows)}

    def row(r: int, group: str) -> Row:
        if r not in index:
            raise ConfigError(f"--rows: the paper has no row {r} (rows 1-{len(points)})")
        k = index[r]
        return Row(r, points.roles[k], {n: float(v) for n, v in zip(points.parameter_names, points.X[k])},
                   float(points.paper_deg[k, j]), stored.get((experiment, r)), group)

    if rows:
        return [row(int(r), "chosen") for r in rows]
    have = sorted((abs(a - points.paper_deg[index[r], j]), r) for (e, r), a in stored.items() if e == experiment)
    if len(have) < top + controls:
        raise ConfigError(f"{experiment}: {len(have)} stored angles in the reproduction folder, fewer than "
                          f"--top {top} + --controls {controls}; give --rows")
    largest = [r for _, r in sorted(have, reverse=True)[:top]]
    small = [r for _, r in have[:controls]]
    return [row(r, "largest_gap") for r in largest] + [row(r, "control") for r in small]


# ----------------------------------------------------------------------------- variants
def volume_equivalent_spheres(material: BulkMaterial) -> BulkMaterial:
    """One sphere per clump template, of the template's volume (so its mass at the same density),
    same number fractions: the same size distribution without the shape. Spheres stay spheres."""
    from warpdem.clump_geometry import ClumpTemplate

    if material.is_spheres:
        return material
    mix = []
    for t, f in material.clumps:
        r = (3.0 * t.volume / (4.0 * math.pi)) ** (1.0 / 3.0)
        mix.append((ClumpTemplate(f"{t.name} sphere", np.zeros((1, 3)), np.array([r]), t.density, t.volume, t.mass,
                                  np.full(3, 0.4 * t.mass * r * r)), f))
    return BulkMaterial(particle=material.particle, clumps=tuple(mix), solids_fraction=material.solids_fraction,
                        name=f"volume-equivalent spheres of {material.name}",
                        source={"type": "volume_equivalent_spheres", "of": material.name})


def variant_law(law: wd.ContactLaw, changes: Mapping[str, Any]) -> wd.ContactLaw:
    """``law`` with some sub-models or options replaced (names as in :class:`warpdem.ContactLaw`)."""
    if not changes:
        return law
    return wd.ContactLaw.from_config({**law.to_config(every_key=True), **changes}, "variant contact_law")


def applies(variant: str, experiment: str) -> bool:
    return experiment in VARIANTS[variant].get("experiments", EXPERIMENTS)


def experiment_for(cfg: cp.CampaignConfig, experiment: str, variant: str, scale: str,
                   overrides: Mapping[str, Any], first_fill: int):
    """The experiment of ``variant``: the config's response for ``experiment`` (its material,
    contact law, plugins, settings) with ``overrides`` (``--settings``), one fill per world from
    ``first_fill``, and the variant's changes."""
    v = VARIANTS[variant]
    resp = next(r for r in cfg.responses if r.experiment == experiment)
    model = cfg.model
    settings = {**dict(resp.settings), **dict(overrides), "fill_per_world": True, "first_fill_index": int(first_fill)}
    if model.material is not None and "material" not in settings:
        settings["material"] = model.material
    law = variant_law(model.contact_law, v.get("contact_law", {}))
    base = make_experiment(experiment, scale, contact_law=law, plugins=model.plugins, **settings)
    extra: dict[str, Any] = dict(v.get("settings", {}))
    if v.get("material") == "volume_equivalent_spheres":
        extra["material"] = volume_equivalent_spheres(base.bulk_material())
    elif v.get("material") == "gravel_low_fill":
        mat = base.bulk_material()
        extra["material"] = BulkMaterial.gravel("low", particle=mat.particle, solids_fraction=mat.solids_fraction,
                                                size_scale=float((mat.source or {}).get("size_scale", 1.0)))
    if "dt_factor" in v:
        mat = extra.get("material", base.bulk_material())
        lim = wd.time_step_limits_for([(mat.particle, *mat.smallest_sphere)], base.v_ref)
        # the step is min(fraction T_R, limit): this fraction gives dt_factor x the recommended step
        extra["dt_rayleigh_fraction"] = float(v["dt_factor"]) * lim.recommended / lim.rayleigh
    if "dt_multiple" in v:
        # above the recommended step, which for the clumps is the Hertz contact-time limit (10 steps
        # per contact at v_ref), not a fraction of the Rayleigh time: an explicit step, forced
        mat = extra.get("material", base.bulk_material())
        lim = wd.time_step_limits_for([(mat.particle, *mat.smallest_sphere)], base.v_ref)
        extra["dt"] = float(v["dt_multiple"]) * lim.recommended
        extra["force_dt"] = True
    if "sections_factor" in v:
        extra["sections"] = int(round(base.sections * float(v["sections_factor"])))
    if "revolutions" in v:
        fd, fr = v["revolutions"]
        extra["discard"] = max(0, int(round(base.discard * float(fd))))
        extra["record"] = max(1, int(round(base.record * float(fr))))
    if not extra:
        return base
    return make_experiment(experiment, scale, contact_law=law, plugins=model.plugins, **{**settings, **extra})


# ----------------------------------------------------------------------------- batches
@dataclass
class Batch:
    variant: str
    experiment: str
    rows: list[Row]
    replicates: int
    first_fill: int
    exp: Any
    setup_key: str
    expected_s: float | None
    worlds: list[tuple[Row, int, int]] = field(default_factory=list)  # (row, replicate, fill index)

    @property
    def label(self) -> str:
        return f"{self.variant}/{self.experiment}"

    def parameter_sets(self) -> list[dict[str, float]]:
        return [dict(r.parameters) for r, _, _ in self.worlds]


def setup_key(variant: str, experiment: str, scale: str, overrides: Mapping[str, Any], exp) -> str:
    """What makes a recorded line this batch's (resume): the variant and its overrides, the
    experiment, its scale and settings overrides, its contact law and material."""
    overrides_of_variant = {k: v for k, v in VARIANTS[variant].items() if k not in ("hypothesis", "cost")}
    doc = {"variant": variant, "overrides": overrides_of_variant,
           "experiment": experiment, "scale": scale, "settings": overrides, "law": exp.contact_law.describe(),
           "material": exp.bulk_material().name}
    return json_digest(doc, 12, default=str)


def expected_seconds(variant: str, experiment: str, worlds: int, on_gpu: bool) -> float | None:
    """Expected GPU time of a batch on one H200 [s] (None on the CPU)."""
    if not on_gpu:
        return None
    factor = float(VARIANTS[variant].get("cost", {}).get(experiment, 1.0))
    return GPU_SECONDS_PER_WORLD[experiment] * max(worlds, MIN_WORLDS_FOR_COST) * factor


def plan_batches(cfg, rows_by_exp: Mapping[str, list[Row]], variants: Sequence[str], scale: str,
                 settings: Mapping[str, Mapping[str, Any]], replicates: int, first_fill: int,
                 on_gpu: bool) -> list[Batch]:
    """One batch per (variant, experiment) where the variant applies, worlds row-major
    (row k, replicate j: world k R + j, fill ``first_fill`` + that)."""
    out = []
    for variant in variants:
        for experiment, rows in sorted(rows_by_exp.items(), key=lambda kv: -GPU_SECONDS_PER_WORLD[kv[0]]):
            if not applies(variant, experiment):
                continue
            exp = experiment_for(cfg, experiment, variant, scale, settings.get(experiment, {}), first_fill)
            worlds = [(r, j, first_fill + k * replicates + j) for k, r in enumerate(rows) for j in range(replicates)]
            key = setup_key(variant, experiment, scale, settings.get(experiment, {}), exp)
            out.append(Batch(variant, experiment, list(rows), replicates, first_fill, exp, key,
                             expected_seconds(variant, experiment, len(worlds), on_gpu), worlds))
    return out


def recorded_keys(path: Path, retry_failed: bool) -> set[tuple]:
    keys = set()
    if not path.exists():
        return keys
    for line in path.read_text().splitlines():
        if not line.strip():
            continue
        try:
            rec = json.loads(line)
        except ValueError:
            continue
        if retry_failed and rec.get("status") != "ok":
            continue
        keys.add((rec.get("setup_key"), rec.get("row"), rec.get("replicate"), rec.get("fill_index")))
    return keys


def is_recorded(batch: Batch, keys: set[tuple]) -> bool:
    return all((batch.setup_key, r.row, j, f) in keys for r, j, f in batch.worlds)


# ----------------------------------------------------------------------------- records
def git_commit() -> str | None:
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                             timeout=10)
        return out.stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        return None


def batch_lines(batch: Batch, results: list | None, error: str | None, wall_s: float, device: str,
                context: Mapping[str, Any]) -> list[dict[str, Any]]:
    """One record per world of ``batch`` (``results`` None: the whole batch failed with ``error``)."""
    exp = batch.exp
    lines = []
    for k, (row, rep, fill) in enumerate(batch.worlds):
        res = results[k] if results is not None else None
        ok = res is not None and res.ok and res.angle_deg is not None
        angle = float(res.angle_deg) if ok else None
        timing = res.timing if res is not None else {}
        lines.append({
            "variant": batch.variant, "experiment": batch.experiment, "angle": ANGLE_LABEL[batch.experiment],
            "response": PAPER_RESPONSE_BY_EXPERIMENT[batch.experiment], "row": row.row, "role": row.role,
            "group": row.group, "replicate": rep, "fill_index": fill, "world": k,
            "parameters": row.parameters, "status": "ok" if ok else "failed",
            "error": (res.error if res is not None else error) if not ok else None,
            "angle_deg": angle, "paper_deg": row.paper_deg,
            "gap_deg": None if angle is None else angle - row.paper_deg, "stored_deg": row.stored_deg,
            "observables": dict(res.observables) if res is not None else {},
            "dt_s": timing.get("dt_s"), "simulated_s": timing.get("simulated_s"),
            "batch_wall_s": round(wall_s, 2), "batch_worlds": len(batch.worlds),
            "spheres_per_world": timing.get("spheres_per_world"), "device": device,
            "scale": exp.scale, "contact_law": exp.contact_law.describe(), "material": exp.bulk_material().name,
            "deviations_from_paper": deviations(exp),
            "variant_overrides": {k2: v for k2, v in VARIANTS[batch.variant].items() if k2 not in ("cost",)},
            "setup_key": batch.setup_key, **context,
        })
    return lines


def deviations(exp) -> dict[str, Any]:
    """The experiment's settings that differ from its paper scale (contact law and material by name)."""
    out = {}
    for k, v in exp.deviations_from_paper().items():
        out[k] = v["value"]
        if k == "contact_law":
            out[k] = exp.contact_law.describe()
    if "material" in out or exp.material is not None:
        out["material"] = exp.bulk_material().name
    return _jsonable(out)


def _jsonable(x: Any) -> Any:
    """Plain JSON values (:func:`warpdem.json_io.jsonable`: numpy values, NaN -> null), anything else as text."""
    return json.loads(json.dumps(jsonable(x), default=str))


def append_lines(path: Path, lines: list[dict[str, Any]]) -> None:
    with path.open("a") as fh:
        for rec in lines:
            fh.write(json.dumps(_jsonable(rec), allow_nan=False) + "\n")
        fh.flush()
        os.fsync(fh.fileno())


def read_lines(path: Path) -> list[dict[str, Any]]:
    if not path.exists():
        return []
    out = []
    for line in path.read_text().splitlines():
        if line.strip():
            try:
                out.append(json.loads(line))
            except ValueError:
                pass
    return out


# ----------------------------------------------------------------------------- summary
def _latest(lines: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per (variant, experiment) the records of its latest setup (a folder run again with other
    settings reports the new ones), and of each (row, replicate, fill) the last record (a rerun
    replaces a failed one)."""
    setup = {(r.get("variant"), r.get("experiment")): r.get("setup_key") for r in lines}
    by = {}
    for rec in lines:
        if rec.get("setup_key") == setup[(rec.get("variant"), rec.get("experiment"))]:
            by[(rec.get("setup_key"), rec.get("row"), rec.get("replicate"), rec.get("fill_index"))] = rec
    return list(by.values())


def _mean_gap(recs: list[dict[str, Any]], pooled_var: float | None) -> tuple[float | None, float | None, int]:
    """Mean over rows of the row's mean gap [deg], its standard error from the fill scatter
    (pooled within-row variance), and the rows."""
    rows: dict[int, list[float]] = {}
    for r in recs:
        if r["status"] == "ok":
            rows.setdefault(r["row"], []).append(r["gap_deg"])
    if not rows:
        return None, None, 0
    mean = float(np.mean([np.mean(g) for g in rows.values()]))
    se = None
    if pooled_var is not None:
        se = math.sqrt(pooled_var * sum(1.0 / len(g) for g in rows.values())) / len(rows)
    return mean, se, len(rows)


def _pooled_variance(recs: list[dict[str, Any]]) -> float | None:
    """Pooled within-row variance of the angles [deg^2] (rows with >= 2 fills), None without."""
    rows: dict[int, list[float]] = {}
    for r in recs:
        if r["status"] == "ok":
            rows.setdefault(r["row"], []).append(r["angle_deg"])
    ss, dof = 0.0, 0
    for a in rows.values():
        if len(a) >= 2:
            ss += float(np.sum((np.asarray(a) - np.mean(a)) ** 2))
            dof += len(a) - 1
    return ss / dof if dof else None


def summarize(lines: list[dict[str, Any]]) -> dict[str, Any]:
    """Per experiment and variant: worlds, step, mean gaps +- SE by group, RMSE, paired change
    against as_run +- SE, the share of as_run's largest-gap mean closed; per row: each variant's
    mean angle. Also the as_run check against the stored reproduction angles."""
    lines = _latest(lines)
    out: dict[str, Any] = {}
    for experiment in EXPERIMENTS:
        recs = [r for r in lines if r["experiment"] == experiment]
        if not recs:
            continue
        variants = [v for v in VARIANTS if any(r["variant"] == v for r in recs)]
        variants += sorted({r["variant"] for r in recs} - set(variants))
        base = {(r["row"], r["replicate"], r["fill_index"]): r["angle_deg"] for r in recs
                if r["variant"] == "as_run" and r["status"] == "ok"}
        table = {}
        for v in variants:
            vr = [r for r in recs if r["variant"] == v]
            pooled = _pooled_variance(vr)
            groups = {}
            for g in ("largest_gap", "control", "chosen", "all"):
                sel = vr if g == "all" else [r for r in vr if r["group"] == g]
                if sel:
                    m, se, n = _mean_gap(sel, pooled)
                    groups[g] = {"mean_gap_deg": m, "se_deg": se, "rows": n}
            row_means = {}
            for r in vr:
                if r["status"] == "ok":
                    row_means.setdefault(r["row"], []).append(r["angle_deg"])
            gaps = [np.mean(a) - next(x["paper_deg"] for x in vr if x["row"] == row) for row, a in row_means.items()]
            diffs = [r["angle_deg"] - base[(r["row"], r["replicate"], r["fill_index"])] for r in vr
                     if r["status"] == "ok" and (r["row"], r["replicate"], r["fill_index"]) in base]
            diffs_big = [r["angle_deg"] - base[(r["row"], r["replicate"], r["fill_index"])] for r in vr
                         if r["status"] == "ok" and r["group"] == "largest_gap"
                         and (r["row"], r["replicate"], r["fill_index"]) in base]
            entry = {
                "worlds": len(vr), "ok": sum(r["status"] == "ok" for r in vr),
                "dt_s": sorted({r["dt_s"] for r in vr if r.get("dt_s")}),
                "fill_sd_deg": None if pooled is None else math.sqrt(pooled),
                "groups": groups, "rmse_deg": float(np.sqrt(np.mean(np.square(gaps)))) if gaps else None,
                "hypothesis": VARIANTS.get(v, {}).get("hypothesis", ""),
                "row_mean_deg": {str(k): float(np.mean(a)) for k, a in sorted(row_means.items())},
                "row_sd_deg": {str(k): (float(np.std(a, ddof=1)) if len(a) > 1 else None)
                               for k, a in sorted(row_means.items())},
            }
            if v != "as_run" and diffs:
                entry["change_vs_as_run_deg"] = float(np.mean(diffs))
                entry["change_se_deg"] = (float(np.std(diffs, ddof=1) / math.sqrt(len(diffs))) if len(diffs) > 1
                                          else None)
                entry["pairs"] = len(diffs)
                if diffs_big:
                    entry["change_largest_gap_deg"] = float(np.mean(diffs_big))
                    entry["change_largest_gap_se_deg"] = (float(np.std(diffs_big, ddof=1) / math.sqrt(len(diffs_big)))
                                                          if len(diffs_big) > 1 else None)
            table[v] = entry
        as_run = table.get("as_run")
        for v, e in table.items():
            g0 = ((as_run or {}).get("groups", {}).get("largest_gap") or {}).get("mean_gap_deg")
            g1 = (e["groups"].get("largest_gap") or {}).get("mean_gap_deg")
            if v != "as_run" and g0 not in (None, 0.0) and g1 is not None:
                e["share_of_gap_closed"] = (abs(g0) - abs(g1)) / abs(g0)
        rows = {}
        for r in recs:
            rows.setdefault(r["row"], {"row": r["row"], "group": r["group"], "role": r["role"],
                                       "paper_deg": r["paper_deg"], "stored_deg": r["stored_deg"],
                                       "parameters": r["parameters"]})
        check = None
        paper_scale = all(r.get("scale") == "paper" for r in recs if r["variant"] == "as_run")
        if as_run is not None and paper_scale:  # the stored angles are the paper-scale reproduction's
            s2 = as_run["fill_sd_deg"] ** 2 if as_run["fill_sd_deg"] is not None else None
            d, var = [], 0.0
            for k, a in as_run["row_mean_deg"].items():
                stored = rows[int(k)]["stored_deg"]
                if stored is None:
                    continue
                n = sum(1 for r in recs if r["variant"] == "as_run" and r["row"] == int(k) and r["status"] == "ok")
                d.append(a - stored)
                if s2 is not None:
                    var += s2 / n + s2  # our mean over n fills, and the stored run's one (shared) fill
            if d:
                mean = float(np.mean(d))
                se = math.sqrt(var) / len(d) if s2 is not None else None
                check = {"rows": len(d), "mean_diff_deg": mean, "se_deg": se,
                         "max_abs_diff_deg": float(np.max(np.abs(d))), "fill_sd_deg": as_run["fill_sd_deg"],
                         "within_noise": None if se is None else bool(abs(mean) <= 2.0 * se)}
        out[experiment] = {"variants": table, "rows": [rows[k] for k in sorted(rows, key=lambda k: (
            {"largest_gap": 0, "chosen": 1, "control": 2}.get(rows[k]["group"], 3), k))], "as_run_check": check}
    return out


def _pm(m: float | None, se: float | None, digits: int = 2) -> str:
    if m is None:
        return "–"
    return f"{m:+.{digits}f}" + ("" if se is None else f" ± {se:.{digits}f}")


def summary_markdown(summary: Mapping[str, Any], meta: Mapping[str, Any]) -> str:
    lines = ["# Causes of the gap to the paper's EDEM, tested (issue 32, item 2)", "",
             f"_`{meta.get('command', '')}`; {meta.get('date', '')}; device {meta.get('device', '?')}; "
             f"scale {meta.get('scale', '?')}; {meta.get('replicates', '?')} fill(s) per row; code "
             f"{', '.join(meta.get('code', []) or ['?'])}._", "",
             "Gap = our angle minus the paper's EDEM angle at the same point [deg]; mean over the rows of each "
             "row's mean over its fills, ± its standard error from the fill-to-fill scatter (pooled within-row "
             "variance). Change = the variant's angle minus as_run's on the same fill, mean over the pairs ± its "
             "standard error. Share closed: how much of as_run's |mean gap| on the largest-gap rows the variant "
             "removes (negative: it widens).", ""]
    for experiment, doc in summary.items():
        label = ANGLE_LABEL[experiment]
        lines += [f"## {label}: {experiment}", ""]
        chk = doc.get("as_run_check")
        if chk:
            verdict = ("within the fill noise" if chk["within_noise"] else
                       "NOT within the fill noise" if chk["within_noise"] is not None else "noise unknown (1 fill)")
            lines += [f"as_run against the stored reproduction angles (one shared fill): mean difference "
                      f"{_pm(chk['mean_diff_deg'], chk['se_deg'])} deg over {chk['rows']} rows (largest "
                      f"{chk['max_abs_diff_deg']:.2f} deg; fill sd "
                      f"{'–' if chk['fill_sd_deg'] is None else format(chk['fill_sd_deg'], '.2f')} deg): "
                      f"{verdict}.", ""]
        groups = [g for g in ("largest_gap", "chosen", "control")
                  if any(g in e["groups"] for e in doc["variants"].values())]
        head = ["variant", "worlds ok", "dt (s)"] + [f"mean gap, {g.replace('_', ' ')} rows (deg)" for g in groups] + \
            ["RMSE (deg)", "change vs as_run (deg)", "change, largest-gap rows (deg)", "share closed",
             "fill sd (deg)", "hypothesis"]
        lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for v, e in doc["variants"].items():
            cells = [f"`{v}`", f"{e['ok']}/{e['worlds']}", ", ".join(f"{x:.3g}" for x in e["dt_s"]) or "–"]
            for g in groups:
                ge = e["groups"].get(g)
                cells.append("–" if ge is None else _pm(ge["mean_gap_deg"], ge["se_deg"]))
            cells += ["–" if e["rmse_deg"] is None else f"{e['rmse_deg']:.2f}",
                      _pm(e.get("change_vs_as_run_deg"), e.get("change_se_deg")),
                      _pm(e.get("change_largest_gap_deg"), e.get("change_largest_gap_se_deg")),
                      "–" if e.get("share_of_gap_closed") is None else f"{100 * e['share_of_gap_closed']:+.0f} %",
                      "–" if e["fill_sd_deg"] is None else f"{e['fill_sd_deg']:.2f}", e["hypothesis"]]
            lines.append("| " + " | ".join(cells) + " |")
        big = "largest_gap" in groups
        key = "change_largest_gap" if big else "change_vs_as_run"
        where = "the largest-gap rows" if big else "its rows"
        se_key = f"{key}_se_deg" if big else "change_se_deg"
        moved = [(v, e) for v, e in doc["variants"].items() if e.get(se_key) is not None
                 and abs(e[f"{key}_deg"]) > 2.0 * e[se_key]]
        lines += [""]
        if moved:
            text = "; ".join(f"`{v}` {e[f'{key}_deg']:+.2f} deg" + (
                f" ({100 * e['share_of_gap_closed']:+.0f} % of the gap closed)" if e.get("share_of_gap_closed")
                is not None else "") for v, e in moved)
            lines += [f"Variants that move {label} on {where} by more than 2 standard errors: {text}.", ""]
        elif len(doc["variants"]) > 1:
            lines += [f"No variant moves {label} on {where} by more than 2 standard errors.", ""]
        variants = list(doc["variants"])
        head = ["row", "group", "role", "paper EDEM", "stored (as run)"] + [f"`{v}`" for v in variants]
        lines += [f"Every row: {label} [deg], each variant's mean over its fills.", "",
                  "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for r in doc["rows"]:
            cells = [str(r["row"]), r["group"].replace("_", " "), r["role"], f"{r['paper_deg']:.1f}",
                     "–" if r["stored_deg"] is None else f"{r['stored_deg']:.1f}"]
            for v in variants:
                m = doc["variants"][v]["row_mean_deg"].get(str(r["row"]))
                sd = doc["variants"][v]["row_sd_deg"].get(str(r["row"]))
                cells.append("–" if m is None else f"{m:.1f}" + ("" if sd is None else f" ± {sd:.1f}"))
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines) + "\n"


def write_summary(out: Path, meta: Mapping[str, Any]) -> dict[str, Any]:
    lines = read_lines(out / "runs.jsonl")
    summary = summarize(lines)
    meta = {**meta, "code": sorted({(r.get("code") or {}).get("source_sha256", "?") for r in lines})}
    (out / "summary.json").write_text(json.dumps(_jsonable({"meta": meta, "summary": summary}), indent=1))
    (out / "summary.md").write_text(summary_markdown(summary, meta))
    return summary


# ----------------------------------------------------------------------------- running
def parse_settings(text: str) -> dict[str, dict[str, Any]]:
    """``--settings`` JSON: keys naming an experiment hold its overrides; any other key applies
    to every experiment."""
    raw = json.loads(text)
    if not isinstance(raw, dict):
        raise ConfigError(f"--settings must be a JSON object, got {text!r}")
    common = {k: v for k, v in raw.items() if k not in EXPERIMENTS}
    return {e: {**common, **dict(raw.get(e, {}))} for e in EXPERIMENTS}


def run(args: argparse.Namespace, argv: Sequence[str]) -> int:
    from warpdem.warp_output import quiet_warp

    quiet_warp(always=True)
    import warp as wp

    on_gpu = str(args.device).startswith("cuda")
    if on_gpu and not args.plan and not wp.is_cuda_available():
        print(f"zhang_gap_causes: --device {args.device}: no CUDA device here (use --device cpu --scale quick)",
              file=sys.stderr)
        return 2
    t_start = time.perf_counter()
    deadline = None if args.time_limit is None else t_start + float(args.time_limit)
    cfg = cp.load_config(args.config)
    points = paper_points(cfg)
    stored = stored_angles(Path(args.results), points)
    rows_by_exp = {e: choose_rows(points, stored, e, args.rows, args.top, args.controls) for e in args.experiments}
    settings = parse_settings(args.settings)
    unknown = sorted(set(args.variants) - set(VARIANTS))
    if unknown:
        raise ConfigError(f"--variants: unknown {unknown}; valid: {list(VARIANTS)}")
    variants = list(dict.fromkeys(args.variants))
    batches = plan_batches(cfg, rows_by_exp, variants, args.scale, settings, args.replicates, args.first_fill, on_gpu)
    out = Path(args.out).resolve()  # Ray workers write checkpoints there, whatever their working folder
    out.mkdir(parents=True, exist_ok=True)
    path = out / "runs.jsonl"
    keys = recorded_keys(path, args.retry_failed)
    # in the order of --variants (priority), the drum (the longer batch) first within a variant
    todo = [b for b in batches if not is_recorded(b, keys)]
    for e, rows in rows_by_exp.items():
        print(f"{e} ({ANGLE_LABEL[e]}): rows " + ", ".join(f"{r.row}" + ("*" if r.group == "control" else "")
                                                         for r in rows) + "  (* control)")
    total = sum(b.expected_s or 0.0 for b in todo)
    for b in batches:
        state = "to run" if b in todo else "recorded"
        cost = "" if b.expected_s is None else f", about {b.expected_s / 60:.1f} GPU-min on one H200"
        print(f"  {b.label}: {len(b.worlds)} worlds{cost} ({state})")
    if on_gpu:
        n_show = args.gpus or (len(wp.get_cuda_devices()) if args.ray and wp.is_cuda_available() else 1)
        print(f"to run: {len(todo)} batches, about {total / 60:.0f} GPU-min on H200 "
              f"(at least {total / 60 / n_show:.0f} min on {n_show} GPU(s))")
    meta = {"command": " ".join(["python benchmarks/zhang_gap_causes.py", *argv]),
            "date": datetime.now(timezone.utc).isoformat(timespec="seconds"), "device": args.device,
            "scale": args.scale, "replicates": args.replicates}
    if args.plan:
        return 0
    context = {"code": code_version(), "git": git_commit(), "host": platform.node(),
               "sitting": datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%S")}
    device_name = args.device
    if on_gpu:
        device_name = wp.get_device(args.device).name

    def time_left() -> float:
        return math.inf if deadline is None else deadline - time.perf_counter()

    def checkpoints(b: Batch) -> BatchCheckpoints | None:
        if args.checkpoint_every is None or args.checkpoint_every < 0:
            return None
        return BatchCheckpoints(out / "checkpoints" / f"{b.variant}-{b.experiment}", float(args.checkpoint_every),
                                keep_until_recorded=True)

    def record(b: Batch, results, error, wall) -> None:
        append_lines(path, batch_lines(b, results, error, wall, device_name, context))
        ck = checkpoints(b)
        if ck is not None:
            clear_checkpoints(ck.folder)
        ok = sum(1 for r in (results or []) if r.ok)
        angles = ", ".join("failed" if not r.ok else f"{r.angle_deg:.1f}" for r in (results or []))
        print(f"{b.label}: {ok}/{len(b.worlds)} ok in {wall:.0f} s" + (f" [{angles}]" if angles else f" ({error})"),
              flush=True)
        write_summary(out, meta)

    stopped = None
    if args.ray:
        n_gpus = args.gpus or (len(wp.get_cuda_devices()) if on_gpu else None)
        ex = RayExecutor(address=args.ray, num_gpus=n_gpus if args.ray == "local" else None,
                         num_cpus=max(2, 2 * (n_gpus or 1)) if args.ray == "local" else None,
                         gpus_per_task=1 if on_gpu else 0, tasks=1)
        ray = ex.connect()
        res = ray.cluster_resources()
        slots = max(1, int(res.get("GPU", 0)) if on_gpu else int(res.get("CPU", 1)))
        # a GPU task in a worker of its own (RayExecutor.remote_function says why)
        remote = ray.remote(num_gpus=1, max_calls=1)(_run_chunk_on_ray) if on_gpu else ray.remote(_run_chunk_on_ray)
        remote = remote.options(num_gpus=1 if on_gpu else 0, num_cpus=1, max_retries=1, retry_exceptions=False)
        inflight: dict[Any, tuple[Batch, float]] = {}
        pending = list(todo)
        while pending or inflight:
            while pending and len(inflight) < slots and time_left() > MIN_START_S:
                b = pending.pop(0)
                ref = remote.remote(b.exp, b.parameter_sets(), "cuda" if on_gpu else "cpu", 0, checkpoints(b))
                inflight[ref] = (b, time.perf_counter())
                print(f"{b.label}: started ({len(b.worlds)} worlds)", flush=True)
            if not inflight:
                break
            done, _ = ray.wait(list(inflight), num_returns=1, timeout=max(1.0, min(30.0, time_left())))
            for ref in done:
                b, t0 = inflight.pop(ref)
                try:
                    results, error = ray.get(ref), None
                except Exception as exc:  # noqa: BLE001 - a failed batch is recorded, the others run on
                    cause = getattr(exc, "cause", None) or exc
                    results, error = None, f"{type(cause).__name__}: {cause}"
                record(b, results, error, time.perf_counter() - t0)
            if not done and time_left() <= 0:
                stopped = [inflight[r][0].label for r in inflight]
                break
        if pending and stopped is None:
            stopped = []
        if stopped is not None:
            stopped += [b.label for b in pending]
        ray.shutdown()
    else:
        for k, b in enumerate(todo):
            if time_left() < MIN_START_S:
                stopped = [x.label for x in todo[k:]]
                break
            print(f"{b.label}: started ({len(b.worlds)} worlds)", flush=True)
            t0 = time.perf_counter()
            try:
                results, error = b.exp.run(b.parameter_sets(), device=args.device, processes=args.processes,
                                           checkpoints=checkpoints(b)), None
            except Exception as exc:  # noqa: BLE001 - as on Ray: the failed batch is recorded, the others run on
                results, error = None, f"{type(exc).__name__}: {exc}"
            record(b, results, error, time.perf_counter() - t0)
    write_summary(out, meta)
    if stopped:
        print(f"stopped at the time limit; not finished: {', '.join(stopped)} (run the same command again: "
              f"recorded batches are skipped, a checkpointed one continues)")
    else:
        print("complete: every batch recorded")
    print(f"summary: {out / 'summary.md'}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], epilog="See the module docstring.")
    ap.add_argument("--device", default="cuda", help="cuda (default) or cpu (with --scale quick: a smoke test)")
    ap.add_argument("--scale", default="paper", choices=["paper", "quick"])
    ap.add_argument("--variants", nargs="+", default=DEFAULT_VARIANTS, metavar="VARIANT",
                    help=f"default: {' '.join(DEFAULT_VARIANTS)}; also: "
                         f"{' '.join(v for v in VARIANTS if v not in DEFAULT_VARIANTS)}")
    ap.add_argument("--experiments", nargs="+", default=list(EXPERIMENTS), choices=list(EXPERIMENTS))
    ap.add_argument("--rows", nargs="+", type=int, default=None,
                    help="paper rows (1-140) for every experiment (default: per angle the --top largest gaps and "
                         "--controls smallest of the reproduction folder)")
    ap.add_argument("--top", type=int, default=6)
    ap.add_argument("--controls", type=int, default=2)
    ap.add_argument("--replicates", type=int, default=2, help="fills per row (one world each)")
    ap.add_argument("--first-fill", type=int, default=0, help="fill index of a batch's first world")
    ap.add_argument("--settings", default="{}",
                    help='experiment setting overrides as JSON: {"fill_mass": 5} for all, or {"drum": {...}}')
    ap.add_argument("--config", default=str(DEFAULT_CONFIG))
    ap.add_argument("--results", default=str(DEFAULT_RESULTS),
                    help="the reproduction folder whose samples.jsonl gives the stored angles")
    ap.add_argument("--out", default="results/zhang_gap_causes")
    ap.add_argument("--ray", default=None, metavar="ADDRESS", help="local or auto: one batch per GPU through Ray")
    ap.add_argument("--gpus", type=int, default=None, help="GPUs of a --ray local cluster (default: all)")
    ap.add_argument("--processes", default=1, help="CPU processes per batch without Ray (cpu only)")
    ap.add_argument("--time-limit", type=float, default=None, metavar="SECONDS")
    ap.add_argument("--checkpoint-every", type=float, default=120.0, metavar="SECONDS",
                    help="save a running batch this often (negative: never)")
    ap.add_argument("--retry-failed", action="store_true")
    ap.add_argument("--plan", action="store_true", help="list the batches and their expected cost; run nothing")
    ap.add_argument("--summary-only", action="store_true", help="rewrite the summary from runs.jsonl")
    args = ap.parse_args(argv)
    if args.replicates < 1:
        ap.error("--replicates must be >= 1")
    if args.summary_only:
        old = Path(args.out) / "summary.json"
        meta = json.loads(old.read_text()).get("meta", {}) if old.exists() else {
            "command": "summary only", "date": datetime.now(timezone.utc).isoformat(timespec="seconds")}
        write_summary(Path(args.out), meta)
        print((Path(args.out) / "summary.md").read_text())
        return 0
    try:
        return run(args, list(sys.argv[1:] if argv is None else argv))
    except ConfigError as exc:
        print(f"zhang_gap_causes: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
