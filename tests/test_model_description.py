"""The model description travels whole: a config's contact law, material and plugins reach the
experiments, fills and builder untouched; parameters are checked against the sub-models'
declarations when a config is loaded (before any DEM runs)."""
import json
import textwrap

import numpy as np
import pytest

import calibration.campaign as cp
import warpdem as wd
from calibration.experiments import make_experiment
from calibration.materials import BulkMaterial
from calibration.model_description import ModelDescription
from warpdem import ConfigError

BASE = {
    "name": "t", "device": "cpu", "processes": 1,
    "parameters": {"mu_s_pp": [0.1, 0.8]},
    "design": {"samples": 6, "held_out": 1, "seed": 0},
    "responses": [{"name": "alpha", "experiment": "baffle", "target": 30.0}],
}

PLUGIN = textwrap.dedent('''
    """A user's cohesion effect, outside the package: constant pull per unit overlap."""
    import warp as wp
    from warpdem.contact import ContactInput, ParameterSpec, SubModel, register

    @register
    class LinearGlue(SubModel):
        kind = "cohesion"
        name = "test_linear_glue"
        parameters = (ParameterSpec("glue_stiffness", "N/m", 0.0, (0.0, 1.0e6), "attractive force per overlap",
                                    design_range=(0.0, 2.0e4), off_value=0.0),)
        reference = "test plugin"

        def make(self, column):
            c_k = column("glue_stiffness")

            @wp.func
            def linear_glue(c: ContactInput, p: wp.array2d(dtype=float)):
                return -p[c.row, c_k] * c.overlap

            return linear_glue
''')


def test_config_bounds_checked_against_declarations_before_any_dem():
    with pytest.raises(ConfigError, match=r"mu_s_pp.*outside its admissible range \[0.0, 10.0\]"):
        cp.parse_config({**BASE, "parameters": {"mu_s_pp": [-0.5, 0.8]}})
    with pytest.raises(ConfigError, match="lower bound 0.8 must be below"):
        cp.parse_config({**BASE, "parameters": {"mu_s_pp": [0.8, 0.8]}})
    with pytest.raises(ConfigError, match="restitution_pp.*outside its admissible range"):
        cp.parse_config({**BASE, "fixed": {"restitution_pp": 1.5}})
    with pytest.raises(ConfigError, match="unknown parameter 'cohesion_energy_density_pp'"):
        cp.parse_config({**BASE, "parameters": {"cohesion_energy_density_pp": [0, 1e4]}})
    with pytest.raises(ConfigError, match="contact_law: unknown key"):
        cp.parse_config({**BASE, "contact_law": {"roling": "epsd"}})
    with pytest.raises(ConfigError, match="unknown cohesion contact model 'glue'"):
        cp.parse_config({**BASE, "contact_law": {"cohesion": "glue"}})


def test_full_law_and_material_reach_the_experiment():
    cfg = cp.parse_config({**BASE, "contact_law": {"rolling": "epsd2", "cohesion": "sjkr"},
                           "material": {"shape": "elongated", "aspect_ratio": 1.5, "diameter": [0.024, 0.030]},
                           "parameters": {"mu_s_pp": [0.1, 0.8], "cohesion_energy_density_pp": [0.0, 5e4],
                                          "aspect_ratio": [1.0, 2.0]}})
    assert cfg.model.contact_law == wd.ContactLaw(rolling="epsd2", cohesion="sjkr")
    assert cfg.space.names == ["mu_s_pp", "cohesion_energy_density_pp", "aspect_ratio"]
    assert cfg.space.parameters[1].unit == "J/m^3"
    exp = make_experiment("baffle", "quick", contact_law=cfg.model.contact_law, material=cfg.model.material)
    assert exp.contact_law is cfg.model.contact_law  # the same value, not rebuilt from a name
    assert "aspect_ratio" in exp.parameter_names and "cohesion_energy_density_pw" in exp.parameter_names
    desc = cfg.model.describe()
    assert desc["contact_law"]["cohesion"] == "sjkr" and desc["contact_law"]["rolling"] == "epsd2"
    assert desc["material"]["shape"] == "elongated"


def test_shape_parameters_make_one_material_per_world_in_one_launch():
    """Worlds of one batch hold different shapes: a shape design runs in one launch."""
    mat = BulkMaterial.shaped("elongated", 0.024, 0.030, aspect_ratio=1.0, size_classes=2)
    exp = make_experiment("cylinder", "quick", material=mat, fill_mass=0.6, lift_speed=0.5, max_time_after_lift=0.3,
                          min_pile_layers=0.0, min_bins=1)
    res = exp.run([{"mu_s_pp": 0.5, "aspect_ratio": 1.0}, {"mu_s_pp": 0.5, "aspect_ratio": 2.2}], device="cpu")
    assert [r.parameters["aspect_ratio"] for r in res] == [1.0, 2.2]
    assert res[0].timing["worlds"] == 2  # one model, two worlds
    spheres = res[0].timing["spheres"]
    bodies = res[0].timing["bodies"]
    assert spheres > bodies  # rods (5 members) in world 1, single spheres in world 0
    with pytest.raises(ConfigError, match="aspect_ratio.*outside its admissible range"):
        exp.run([{"mu_s_pp": 0.5, "aspect_ratio": 5.0}], device="cpu")


def test_plugin_submodel_from_a_campaign_config_is_calibrated(tmp_path, monkeypatch):
    """A sub-model in a file outside the package, named in a campaign config, is loaded, compiled into
    the contact kernel and its parameter designed over and recorded, with no other edit."""
    (tmp_path / "my_glue.py").write_text(PLUGIN)
    cfg_doc = {**BASE, "plugins": ["my_glue.py"], "contact_law": {"rolling": "none", "cohesion": "test_linear_glue"},
               "parameters": {"glue_stiffness_pp": [0.0, 2.0e4]}, "fixed": {"mu_s_pp": 0.5, "mu_s_pw": 0.5},
               "output": str(tmp_path / "out")}
    path = tmp_path / "campaign.json"
    path.write_text(json.dumps(cfg_doc))
    cfg = cp.load_config(path)
    assert cfg.space.names == ["glue_stiffness_pp"] and cfg.space.parameters[0].unit == "N/m"
    seen = []

    def fake_run(self, parameter_sets, device=None, progress=False, processes=1, **kwargs):
        # the experiment got the law with the plugin's sub-model, and builds a model with it
        assert self.contact_law.cohesion == "test_linear_glue"
        seen.extend(p["glue_stiffness_pp"] for p in parameter_sets)
        return orig_run(self, parameter_sets, device=device, progress=False, processes=1, **kwargs)

    from calibration.experiments.common import Experiment

    orig_run = Experiment.run
    monkeypatch.setattr(Experiment, "run", fake_run)
    resp = cfg.responses[0]
    resp.settings.update(fill_mass=3.0, lift_to=0.2, max_time_after_lift=0.5, min_bins=2)
    recs = cp.run_response(resp, [{"glue_stiffness_pp": 0.0}, {"glue_stiffness_pp": 1.5e4}], cfg)
    assert seen == [0.0, 1.5e4]
    assert len(recs) == 2
    # the plugin's parameter really went into the model's per-world table
    from calibration.experiments import make_experiment as mk

    exp = mk("baffle", "quick", contact_law=cfg.model.contact_law, plugins=cfg.model.plugins)
    assert "glue_stiffness_pw" in exp.parameter_names


def test_model_description_errors_name_the_problem():
    d = ModelDescription(wd.ContactLaw(rolling="epsd"))
    with pytest.raises(ConfigError, match="mu_r_pp must be a number"):
        d.check_value("mu_r_pp", "high")
    with pytest.raises(ConfigError, match=r"must be \[lower, upper\]"):
        d.check_bounds("mu_r_pp", [0.1])
    with pytest.raises(ConfigError, match="plugins: file not found"):
        ModelDescription.from_config({"plugins": ["nope.py"]})
    assert np.isclose(d.check_value("mu_r_pp", 0.2), 0.2)
