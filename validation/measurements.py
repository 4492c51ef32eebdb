"""Measurement files -> the diagnosis's :class:`~validation.observables.Observations`, and back.

:func:`load_observations` reads a measurement file (``warpdem-measurements/2``, or version 1,
docs/measurement_format.md) and gives one :class:`~validation.observables.Observable` per
experiment, condition and quantity: key ``"drum/15rpm/dynamic_angle"``, the repeats in the
file's unit (deg, kg/m^3, m, ...), the condition's protocol settings as ``condition`` (e.g.
``{"rpm": 15}``), the reading resolution, and "no pile formed" as a censored observable (every
repeat below the detection limit, :meth:`Observable.below_detection`).

:func:`write_observations` writes observables (e.g. synthetic "lab" data made with the engine)
to a version-2 file that :func:`load_observations` reads back identically.

Not carried by :class:`Observations`: the file's ``material`` (what was measured), title and
source; read them from :func:`calibration.measurement.load_measurements`.
"""

from __future__ import annotations

import os
from typing import Any, Mapping, Sequence

from calibration.measurement.errors import MeasurementFileError
from calibration.measurement.records import (
    MeasurementFile,
    ObservationRecord,
    load_measurements,
    write_measurements_v2,
)

from .observables import Observable, Observations

__all__ = [
    "load_observations",
    "observations_from_file",
    "observable_from_record",
    "observations_from_records",
    "record_from_observable",
    "write_observations",
]


def _plain_label(rec: ObservationRecord) -> str:
    """``"dynamic angle, drum 15rpm"``: plain words for a record without a label."""
    return f"{rec.quantity.replace('_', ' ')}, {rec.experiment} {rec.condition}"


def _resolution(rec: ObservationRecord, default_resolution: float | Mapping[str, float] | None) -> float:
    """The record's resolution [unit], else the default for its quantity, else for its unit."""
    if rec.resolution > 0.0 or default_resolution is None:
        return rec.resolution
    if isinstance(default_resolution, Mapping):
        return float(default_resolution.get(rec.quantity, default_resolution.get(rec.unit, 0.0)))
    return float(default_resolution)


def observable_from_record(rec: ObservationRecord, *,
                           default_resolution: float | Mapping[str, float] | None = None,
                           auto_label: bool = True, file: str = "<records>", where: str | None = None) -> Observable:
    """One :class:`Observable` from one record.

    default_resolution: reading resolution [unit] where the record gives none: a number, or a
    mapping by quantity or unit (e.g. ``{"deg": 0.1}``); a single repeat needs one.
    auto_label: plain words (``"dynamic angle, drum 15rpm"``) where the record has no label.
    A record the observable refuses (one repeat without a resolution; repeats with a value and
    censored ones in one condition) raises :class:`MeasurementFileError` naming ``file`` and
    ``where`` (default: the record's key).
    """
    label = rec.label or (_plain_label(rec) if auto_label else "")
    resolution = _resolution(rec, default_resolution)
    try:
        if rec.n_censored and not rec.repeats:
            return Observable.below_detection(rec.key, rec.experiment, rec.quantity, rec.unit, rec.n_censored,
                                              rec.censor_limit, dict(rec.settings), label, resolution)
        return Observable(rec.key, rec.experiment, rec.quantity, rec.unit, rec.repeats, dict(rec.settings), label,
                          resolution, rec.n_censored, rec.censor_limit)
    except ValueError as e:
        hint = ""
        if len(rec.repeats) == 1 and not rec.n_censored and resolution == 0.0:
            hint = " (give its 'resolution' in the file, or default_resolution)"
        raise MeasurementFileError(file, where or rec.key, f"{e}{hint}") from e


def _where(mf: MeasurementFile, rec: ObservationRecord) -> str:
    """The dotted place of a record in a version-2 file; its key for version 1."""
    if mf.version == 2:
        return f"experiments.{rec.experiment}.conditions.{rec.condition}.observables.{rec.quantity}"
    return rec.key


def observations_from_records(records: Sequence[ObservationRecord], *, origins: Sequence[str] | None = ("lab",),
                              default_resolution: float | Mapping[str, float] | None = None,
                              auto_label: bool = True, file: str = "<records>") -> Observations:
    """:class:`Observations` from records (those whose origin is in ``origins``; None: all), in order.

    See :func:`observable_from_record` for the options. Raises ValueError when no record is left.
    """
    kept = [r for r in records if origins is None or r.origin in origins]
    if not kept:
        raise ValueError(f"{file}: no observations of origin {', '.join(origins or ())} "
                         f"(found {sorted({r.origin for r in records})})")
    return Observations([observable_from_record(r, default_resolution=default_resolution, auto_label=auto_label,
                                                file=file) for r in kept])


def observations_from_file(mf: MeasurementFile, *, origins: Sequence[str] | None = ("lab",),
                           default_resolution: float | Mapping[str, float] | None = None,
                           auto_label: bool = True,
                           diagnostic_dir: str | os.PathLike | None = None) -> Observations:
    """:class:`Observations` of a loaded measurement file (images and videos are measured;
    their diagnostic pictures go to ``diagnostic_dir``). Errors name the file and the key."""
    records = [r for r in mf.observations(diagnostic_dir=diagnostic_dir) if origins is None or r.origin in origins]
    if not records:
        raise MeasurementFileError(mf.path, "experiments", f"no observations of origin {', '.join(origins or ())}")
    return Observations([observable_from_record(r, default_resolution=default_resolution, auto_label=auto_label,
                                                file=mf.path, where=_where(mf, r)) for r in records])


def load_observations(path: str | os.PathLike, *, origins: Sequence[str] | None = ("lab",),
                      default_resolution: float | Mapping[str, float] | None = None,
                      experiments: Mapping[str, Any] | None = None, build: bool = False,
                      auto_label: bool = True, diagnostic_dir: str | os.PathLike | None = None) -> Observations:
    """Read a measurement file (version 1 or 2) as :class:`Observations`.

    origins: keep conditions of these origins ("lab" by default; a v1 file's reference
    simulations are left out); None keeps all. default_resolution: see
    :func:`observable_from_record`. experiments / build: check the file's experiment and setting
    names against a mapping (the registered experiments: ``calibration.experiments.EXPERIMENTS``;
    see :func:`calibration.measurement.check_settings`).
    Raises :class:`MeasurementFileError` naming the file and the key.
    """
    mf = load_measurements(path, experiments=experiments, build=build)
    return observations_from_file(mf, origins=origins, default_resolution=default_resolution,
                                  auto_label=auto_label, diagnostic_dir=diagnostic_dir)


def record_from_observable(obs: Observable, *, origin: str = "lab", description: str = "") -> ObservationRecord:
    """The record of an :class:`Observable` whose key is ``"experiment/condition/quantity"``
    (its experiment and quantity must match the key's)."""
    parts = obs.key.split("/")
    if len(parts) != 3 or parts[0] != obs.experiment or parts[2] != obs.quantity:
        raise ValueError(f"observable {obs.key!r}: a measurement file needs keys 'experiment/condition/quantity' "
                         f"(here {obs.experiment}/<condition>/{obs.quantity})")
    return ObservationRecord(obs.experiment, parts[1], obs.quantity, obs.unit, obs.repeats, dict(obs.condition),
                             obs.n_below_detection, obs.detection_limit, obs.resolution, obs.label, description,
                             origin)


def write_observations(path: str | os.PathLike, observations: Observations | Sequence[Observable], *,
                       title: str = "", source: str = "", notes: str = "",
                       material: Mapping[str, Any] | None = None, origin: str = "lab") -> MeasurementFile:
    """Write observables to a version-2 measurement file (see
    :func:`calibration.measurement.write_measurements_v2`) and return it loaded; reading it with
    :func:`load_observations` gives the same observables (labels included)."""
    records = [record_from_observable(o, origin=origin) for o in observations]
    return write_measurements_v2(path, records, title=title, source=source, notes=notes, material=material)
