"""A diagnosis setting is declared once (issue 30, item 3): the config's ``diagnosis:`` section is
derived from :class:`validation.settings.DiagnosisSettings` (type, default, bounds), and both
refuse the same values."""
from __future__ import annotations

import dataclasses

import pytest
from pydantic import ValidationError

from validation.config import DiagnosisSection
from validation.settings import BOUNDS, DiagnosisSettings


def test_section_has_every_setting_with_its_default():
    settings = {f.name: f.default for f in dataclasses.fields(DiagnosisSettings) if f.name != "add"}
    assert set(DiagnosisSection.model_fields) == set(settings)
    assert DiagnosisSection().model_dump() == settings
    assert DiagnosisSettings(**DiagnosisSection().model_dump()) == DiagnosisSettings()


@pytest.mark.parametrize("field", [f for f in dataclasses.fields(DiagnosisSettings) if f.metadata.get(BOUNDS)],
                         ids=lambda f: f.name)
def test_a_bound_is_refused_by_both(field):
    bounds = field.metadata[BOUNDS]
    bad = bounds["ge"] - 1 if "ge" in bounds else bounds["gt"]
    with pytest.raises(ValidationError, match=field.name):
        DiagnosisSection(**{field.name: bad})
    with pytest.raises(ValueError, match=f"DiagnosisSettings.{field.name}"):
        DiagnosisSettings(**{field.name: bad})
    if "le" in bounds:
        with pytest.raises(ValidationError, match=field.name):
            DiagnosisSection(**{field.name: bounds["le"] * 2})
        with pytest.raises(ValueError, match=f"DiagnosisSettings.{field.name}"):
            DiagnosisSettings(**{field.name: bounds["le"] * 2})
