"""Discovery of contact sub-models: package scan, entry points, user files (load_module),
and the registration rules (idempotent re-import, clear errors)."""
import importlib.metadata
import pickle
import sys
import textwrap

import numpy as np
import pytest

import warpdem as wd
from warpdem import ConfigError, contact
from warpdem.contact import REGISTRY, ContactInput, ContactPluginWarning, SubModel, load_module, register
from warpdem.materials import effective_youngs_modulus

R = np.float32(0.009).item()

MY_EFFECTS = '''
"""A user's sub-model file, outside the warpdem package."""
import warp as wp

from warpdem.contact import ContactInput, ParameterSpec, SubModel, register


@register
class ConstantPull(SubModel):
    """Constant attraction while in contact (a test effect)."""

    kind = "cohesion"
    name = "my_cohesion"
    parameters = (ParameterSpec("pull_force", "N", 0.0, (0.0, 5.0), "constant attraction", ),)
    reference = "test"

    def make(self, column):
        c_pull = column("pull_force")

        @wp.func
        def my_cohesion(c: ContactInput, p: wp.array2d(dtype=float)):
            return -p[c.row, c_pull]

        return my_cohesion
'''

ROLLING_TEMPLATE = '''
import warp as wp

from warpdem.contact import ContactInput, SubModel, register


class {cls}(SubModel):
    kind = "rolling"
    name = "{name}"

    def make(self, column):
        @wp.func
        def f(c: ContactInput, p: wp.array2d(dtype=float), fn: float, spring: wp.vec3):
            return wp.vec3(0.0), spring

        return f
'''


def rolling_module(cls: str, name: str, decorate: bool = True) -> str:
    src = ROLLING_TEMPLATE.format(cls=cls, name=name)
    return src.replace(f"class {cls}", f"@register\nclass {cls}") if decorate else src


@pytest.fixture(autouse=True)
def clean_registry():
    """Each test leaves the registry and sys.modules as it found them."""
    saved = {k: dict(v) for k, v in REGISTRY.items()}
    modules = set(sys.modules)
    yield
    for k, v in saved.items():
        REGISTRY[k].clear()
        REGISTRY[k].update(v)
    for name in set(sys.modules) - modules:
        if name.startswith(("warpdem_plugin_", "wd_test_", "warpdem.contact.wd_test_")):
            del sys.modules[name]


def test_builtins_found_by_scanning_the_package():
    """The package's own sub-models (a plugin another test loaded may be registered too: it is not
    a built-in, so it is left out of the comparison, whatever order the tests run in)."""
    def builtins(kind: str) -> list[str]:
        return [n for n in contact.available(kind) if contact.REGISTRY[kind][n].__module__.startswith("warpdem.")]

    assert {"hertz_mindlin", "none", "rolling", "cohesion"} <= set(contact.BUILTIN_MODULES)
    assert builtins("cohesion") == ["none", "sjkr", "sjkr2", "sjkr2_reduced", "sjkr_reduced"]
    assert builtins("rolling") == ["cdt", "cdt_body_arm", "cdt_liggghts", "epsd", "epsd2", "none"]


def test_a_new_file_in_the_package_folder_is_one_new_effect(tmp_path, monkeypatch):
    """The scan imports every module on the package path: a file is all a new effect needs."""
    (tmp_path / "wd_test_scan_effect.py").write_text(rolling_module("ScannedRolling", "wd_test_scanned"))
    monkeypatch.setattr(contact, "__path__", [*contact.__path__, str(tmp_path)])
    assert "wd_test_scan_effect" in contact._import_package_modules()
    assert "wd_test_scanned" in contact.available("rolling")
    assert wd.ContactLaw(rolling="wd_test_scanned").submodels["rolling"].name == "wd_test_scanned"


def test_user_file_loaded_with_load_module_runs_in_a_model(tmp_path):
    path = tmp_path / "my_effects.py"
    path.write_text(MY_EFFECTS)
    with pytest.raises(ConfigError, match="load_module"):
        wd.ContactLaw(cohesion="my_cohesion")  # not loaded yet: the error says how
    module = load_module(str(path))
    assert load_module(path) is module  # same file again: the module already loaded
    assert load_module("my_effects.py", relative_to=tmp_path) is module

    law = wd.ContactLaw(cohesion="my_cohesion")
    assert law.parameter_names == ["restitution_pp", "restitution_pw", "pull_force_pp", "pull_force_pw",
                                   "mu_s_pp", "mu_s_pw"]
    spec = law.specs["pull_force"]
    assert (spec.unit, spec.bounds, spec.default) == ("N", (0.0, 5.0), 0.0)
    assert pickle.loads(pickle.dumps(law)) == law

    # two spheres overlapping by delta: contact force = Hertz - pull
    delta, pull = 1.0e-5, 0.5
    b = wd.ModelBuilder(contact_law=law, gravity=(0.0, 0.0, 0.0))
    b.add_material(wd.GRAVEL)
    b.add_spheres([(0.0, 0.0, 0.0), (2 * R - delta, 0.0, 0.0)], R, "gravel")
    b.set_contact_parameters(pull_force_pp=pull)
    with pytest.raises(ConfigError, match="pull_force_pw"):
        b.set_contact_parameters(pull_force_pw=6.0)  # outside the declared bounds
    model = b.finalize("cpu")
    sim = wd.Simulation(model, 1e-6)
    x = sim.state.body_q.numpy().astype(np.float64)
    sim.run(1)
    d = 2 * R - (x[1, 0] - x[0, 0])
    hertz = 4.0 / 3.0 * effective_youngs_modulus(wd.GRAVEL, wd.GRAVEL) * np.sqrt(R / 2) * d**1.5
    f = sim.solver.sphere_f.numpy()
    assert -f[0, 0] == pytest.approx(hertz - pull, rel=1e-3)  # attractive: pull > Hertz here
    sim.run(4)
    assert np.all(np.isfinite(sim.state.body_q.numpy()))


def test_load_module_errors_name_the_problem(tmp_path):
    with pytest.raises(ConfigError, match="not found.*nowhere.py"):
        load_module(str(tmp_path / "nowhere.py"))
    with pytest.raises(ConfigError, match="module 'wd_test_no_such_module' not found"):
        load_module("wd_test_no_such_module")
    with pytest.raises(ConfigError, match="neither a .py file nor a dotted module name"):
        load_module("my effects")
    bad = tmp_path / "broken_effects.py"
    bad.write_text("import warp as wp\nraise RuntimeError('oops in the plugin')\n")
    with pytest.raises(ConfigError, match="broken_effects.py failed to import: RuntimeError: oops in the plugin"):
        load_module(bad)
    assert not any(m.startswith("warpdem_plugin_broken_effects") for m in sys.modules)


def test_a_second_class_under_a_taken_name_is_an_error(tmp_path):
    (tmp_path / "first.py").write_text(rolling_module("FirstRolling", "wd_test_taken"))
    (tmp_path / "second.py").write_text(rolling_module("SecondRolling", "wd_test_taken"))
    load_module(tmp_path / "first.py")
    with pytest.raises(ConfigError, match=r"second.py: .*'wd_test_taken' is already registered by .*FirstRolling"):
        load_module(tmp_path / "second.py")
    with pytest.raises(ConfigError, match="already registered"):
        register(type("OtherRolling", (REGISTRY["rolling"]["wd_test_taken"],), {}))


def test_register_is_idempotent_for_the_same_class():
    def declare(tag: int):
        class Redefined(SubModel):  # same qualified name each call: a re-import
            kind = "cohesion"
            name = "wd_test_redefined"
            version = tag

            def make(self, column):
                raise NotImplementedError

        return Redefined

    first = register(declare(1))
    second = register(declare(2))
    assert first is not second and REGISTRY["cohesion"]["wd_test_redefined"] is second
    register(second)
    # a law naming it compiles against the class registered now (not a stale kernel)
    assert wd.ContactLaw(cohesion="wd_test_redefined").implementation[1] is second


def test_malformed_declarations_are_clear_errors():
    from warpdem.contact import ParameterSpec

    def cls(**attrs):
        body = {"kind": "cohesion", "name": "wd_test_bad", "make": lambda self, column: None, **attrs}
        return type("Bad", (SubModel,), body)

    with pytest.raises(ConfigError, match="unknown sub-model kind 'adhesion'"):
        register(cls(kind="adhesion"))
    with pytest.raises(ConfigError, match="'name' must be an identifier"):
        register(cls(name="my cohesion"))
    with pytest.raises(ConfigError, match="default of 'k' = 2.0 outside its bounds"):
        register(cls(parameters=(ParameterSpec("k", "-", 2.0, (0.0, 1.0), ""),)))
    with pytest.raises(ConfigError, match="does not implement make"):
        register(type("NoMake", (SubModel,), {"kind": "cohesion", "name": "wd_test_nomake"}))
    # a parameter shared by two sub-models must be declared identically
    register(cls(parameters=(ParameterSpec("mu_s", "-", 0.3, (0.0, 1.0), "another mu_s"),)))
    with pytest.raises(ConfigError, match="parameter 'mu_s' is declared differently"):
        wd.ContactLaw(cohesion="wd_test_bad")


def write_distribution(site, entry_points: str) -> None:
    info = site / "warpdem_test_plugin-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: warpdem-test-plugin\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(entry_points)


def test_installed_entry_point_plugins_are_discovered_and_broken_ones_warn(tmp_path, monkeypatch):
    """A distribution on sys.path (a dist-info folder, as pip installs it) declaring the group
    ``warpdem.contact_models``: a module entry point, a class entry point, and a broken one."""
    (tmp_path / "wd_test_ep_module.py").write_text(rolling_module("EpModuleRolling", "wd_test_ep_module"))
    (tmp_path / "wd_test_ep_classes.py").write_text(rolling_module("EpClassRolling", "wd_test_ep_class", False))
    (tmp_path / "wd_test_ep_broken.py").write_text("raise ImportError('needs the package wd_missing_dep')\n")
    write_distribution(tmp_path, textwrap.dedent("""\
        [warpdem.contact_models]
        module_plugin = wd_test_ep_module
        class_plugin = wd_test_ep_classes:EpClassRolling
        broken_plugin = wd_test_ep_broken
        """))
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.warns(ContactPluginWarning) as caught:
        loaded = contact.discover_plugins()
    assert "module_plugin = wd_test_ep_module" in loaded
    assert "class_plugin = wd_test_ep_classes:EpClassRolling" in loaded
    assert {"wd_test_ep_module", "wd_test_ep_class"} <= set(contact.available("rolling"))
    (message,) = [str(w.message) for w in caught]
    assert "'broken_plugin' = 'wd_test_ep_broken'" in message
    assert "warpdem-test-plugin" in message and "needs the package wd_missing_dep" in message
    assert contact.discover_plugins(group="wd_test_no_such_group") == []


def test_entry_points_are_queried_for_the_warpdem_group(monkeypatch):
    """Simulated with a patched importlib.metadata.entry_points: the group asked for is
    ``warpdem.contact_models``, and an entry point naming a missing module only warns."""
    asked = []

    def fake_entry_points(**kw):
        asked.append(kw)
        return [importlib.metadata.EntryPoint("ghost", "wd_test_ghost_module", kw["group"])]

    monkeypatch.setattr(importlib.metadata, "entry_points", fake_entry_points)
    with pytest.warns(ContactPluginWarning, match="'ghost' = 'wd_test_ghost_module'.*ModuleNotFoundError"):
        assert contact.discover_plugins() == []
    assert asked == [{"group": "warpdem.contact_models"}]


def test_the_documented_example_works(tmp_path):
    """docs/adding_an_effect.md: its one-file example loads, and the DMT pull-off it
    implements (F = -2 pi w R*) is what a two-sphere model feels."""
    import math
    import re
    from pathlib import Path

    doc = (Path(__file__).resolve().parents[1] / "docs" / "adding_an_effect.md").read_text()
    example = re.findall(r"```python\n(.*?)```", doc, re.S)[0]
    assert "@register" in example
    (tmp_path / "my_effects.py").write_text(example)
    load_module(tmp_path / "my_effects.py")
    law = wd.ContactLaw(cohesion="dmt", rolling="epsd2")
    assert law.parameter_names == ["restitution_pp", "restitution_pw", "work_of_adhesion_pp", "work_of_adhesion_pw",
                                   "mu_s_pp", "mu_s_pw", "mu_r_pp", "mu_r_pw"]
    assert law.specs["work_of_adhesion"].unit == "J/m^2"
    delta, w = 1.0e-5, 0.2  # pull 5.7e-3 N, Hertz 1.55e-2 N
    b = wd.ModelBuilder(contact_law=law, gravity=(0.0, 0.0, 0.0))
    b.add_material(wd.GRAVEL)
    b.add_spheres([(0.0, 0.0, 0.0), (2 * R - delta, 0.0, 0.0)], R, "gravel")
    b.set_contact_parameters(work_of_adhesion_pp=w, work_of_adhesion_pw=0.0)
    sim = wd.Simulation(b.finalize("cpu"), 1e-6)
    x = sim.state.body_q.numpy().astype(np.float64)
    sim.run(3)
    d = 2 * R - (x[1, 0] - x[0, 0])
    hertz = 4.0 / 3.0 * effective_youngs_modulus(wd.GRAVEL, wd.GRAVEL) * np.sqrt(R / 2) * d**1.5
    # forces of the third step: the spheres barely moved (|dx| ~ 1e-12 m)
    f = sim.solver.sphere_f.numpy()
    assert -f[0, 0] == pytest.approx(hertz - 2 * math.pi * w * R / 2, rel=1e-3)
