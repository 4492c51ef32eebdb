"""Which unmeasured conditions to forecast when candidate effects tie (``proposals: auto``).

:func:`enumerate_proposals` searches the whole space a lab can reach from what it measured:

* at every **measured condition**, each observable the experiment reports that was not measured
  there (e.g. the bulk density of a baffle test whose angle alone was read). Its DEM worlds are
  the measured ones, so it costs no new simulation;
* every **setting the lab can change** (the experiment's ``LAB_SETTINGS``,
  :mod:`calibration.experiments.lab_effort`), one at a time, at each of its declared values
  (multiples of the measured value), from each measured condition, with every observable;
* every **registered experiment not measured**, at its standard set-up, with every observable.

Conditions equal to a measured one are skipped; so is one the experiment refuses (a fill fraction
of 1) or the machine cannot hold (the ``check`` callable). Every observable of one condition comes
from the same DEM runs, so the DEM cost is per new condition, and at most ``max_conditions`` new
conditions are kept (:data:`DEFAULT_MAX_PROPOSED_CONDITIONS`): the settings are taken in turns,
cheapest lab effort first, so each setting is tried once before any is tried twice. The plan names
every condition left out and why (:attr:`ProposalPlan.dropped`).

The lab effort of a proposal (:func:`lab_hours`) is in lab hours for its ``n_repeats`` repeats: the
changed setting's ``change_hours`` plus the repeats at its ``repeat_hours``; an unmeasured
experiment's ``setup_hours`` plus its repeats; a measured condition's repeats alone.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Callable, Mapping, Sequence

from calibration.experiments import EXPERIMENTS
from calibration.experiments.lab_effort import LabEffort, LabSetting, round_3
from warpdem import ConfigError

from .forward import ProposedMeasurement

__all__ = ["DEFAULT_MAX_PROPOSED_CONDITIONS", "ProposedCondition", "DroppedCondition", "ProposalPlan",
           "enumerate_proposals", "lab_hours", "lab_settings", "lab_effort"]

#: new conditions (DEM worlds of their own) forecast at most, by default (config: max_proposed_conditions)
DEFAULT_MAX_PROPOSED_CONDITIONS = 6

#: the effort assumed for an experiment that declares none: one lab hour a repeat, a day to set up
_UNDECLARED_EFFORT = LabEffort(1.0, 8.0, "no effort declared by the experiment")


def lab_settings(experiment: str) -> tuple[LabSetting, ...]:
    """The settings a lab can change in ``experiment`` (its ``LAB_SETTINGS``; none when undeclared)."""
    return tuple(getattr(EXPERIMENTS[experiment], "LAB_SETTINGS", ()))


def lab_effort(experiment: str) -> LabEffort:
    """The lab effort of one repeat of ``experiment`` (its ``LAB_EFFORT``)."""
    return getattr(EXPERIMENTS[experiment], "LAB_EFFORT", None) or _UNDECLARED_EFFORT


@dataclass(frozen=True)
class ProposedCondition:
    """One condition to forecast: its experiment, its full settings and what it costs the lab.

    settings : the condition to simulate (the measured condition's settings plus the change).
    change : the lab setting changed (None: a measured condition, or an unmeasured experiment).
    words : plain words, e.g. ``"drum speed 60 rpm (measured: 30 rpm)"``.
    lab_hours : lab hours [h] of ``n_repeats`` repeats there, any change or set-up included.
    new : True when it needs DEM worlds of its own (False: a measured condition's worlds serve).
    quantities : the observables to forecast there.
    name : the condition's name in keys (no "/" nor white space), e.g. ``"30rpm+fill_fraction=0.25"``.
    """

    experiment: str
    settings: Mapping[str, Any]
    change: str | None
    words: str
    lab_hours: float
    new: bool
    quantities: tuple[str, ...]
    name: str

    def __post_init__(self) -> None:
        object.__setattr__(self, "settings", MappingProxyType(dict(self.settings)))
        object.__setattr__(self, "lab_hours", round(float(self.lab_hours), 3))

    def describe(self) -> str:
        return f"{self.experiment} at {self.words} ({self.lab_hours:.2g} lab hours)"


@dataclass(frozen=True)
class DroppedCondition:
    """A condition the search reached but does not forecast, and why."""

    experiment: str
    settings: Mapping[str, Any]
    words: str
    lab_hours: float | None
    reason: str

    def __post_init__(self) -> None:
        object.__setattr__(self, "settings", MappingProxyType(dict(self.settings)))
        if self.lab_hours is not None:
            object.__setattr__(self, "lab_hours", round(float(self.lab_hours), 3))

    def describe(self) -> str:
        hours = f", {self.lab_hours:.2g} lab hours" if self.lab_hours is not None else ""
        return f"{self.experiment} at {self.words}{hours}: {self.reason}"

    def to_dict(self) -> dict[str, Any]:
        return {"experiment": self.experiment, "settings": dict(self.settings), "words": self.words,
                "lab_hours": self.lab_hours, "reason": self.reason}


@dataclass(frozen=True)
class ProposalPlan:
    """The proposals to forecast, the conditions they come from, and the conditions left out."""

    proposals: tuple[ProposedMeasurement, ...]
    conditions: tuple[ProposedCondition, ...]
    dropped: tuple[DroppedCondition, ...]
    max_conditions: int

    @property
    def new_conditions(self) -> int:
        """Conditions kept that need DEM worlds of their own (at most ``max_conditions``)."""
        return sum(c.new for c in self.conditions)

    def not_forecast(self) -> tuple[str, ...]:
        """One line per condition left out: where, its lab effort, why."""
        return tuple(d.describe() for d in self.dropped)


# ---------------------------------------------------------------------------- condition arithmetic
def _plain(v: Any) -> Any:
    """A setting value in a comparable, JSON-able form (ints as floats, sequences as lists)."""
    if isinstance(v, bool) or v is None or isinstance(v, str):
        return v
    if isinstance(v, (int, float)):
        return float(v)
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    return str(v)


def _text(v: Any) -> str:
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return f"{float(v):g}"
    if isinstance(v, (list, tuple)):
        return "(" + ", ".join(_text(x) for x in v) + ")"
    return str(v)


def _with_unit(v: Any, unit: str) -> str:
    return _text(v) if unit in ("", "-", "1") else f"{_text(v)} {unit}"


class _Frame:
    """One experiment at the diagnosis's scale and settings: the value of any setting of a condition."""

    def __init__(self, experiment: str, scale: str, extra: Mapping[str, Any]):
        self.experiment = experiment
        self.cls = EXPERIMENTS[experiment]
        self.extra = {k: v for k, v in extra.items() if k != "scale"}
        self.scale = str(extra.get("scale", scale))
        base = self.build({})
        self.defaults = {name: getattr(base, name) for name in self.cls.field_names()}

    def build(self, condition: Mapping[str, Any]):
        """The experiment at ``condition`` (ConfigError when it refuses the settings)."""
        return self.cls.from_config(self.scale, **{**self.extra, **condition})

    def value(self, condition: Mapping[str, Any], name: str) -> Any:
        return condition[name] if name in condition else self.defaults.get(name)

    def canonical(self, condition: Mapping[str, Any]) -> str:
        """A string equal for two conditions exactly when they simulate the same settings."""
        keys = set(condition) | {s.name for s in lab_settings(self.experiment)}
        return json.dumps({k: _plain(self.value(condition, k)) for k in sorted(keys)}, sort_keys=True)

    def changed(self, condition: Mapping[str, Any], measured: Mapping[str, Any]) -> list[str]:
        """The settings in which ``condition`` differs from ``measured``."""
        keys = sorted(set(condition) | set(measured))
        return [k for k in keys if _plain(self.value(condition, k)) != _plain(self.value(measured, k))]


def _change_hours(experiment: str, changed: Sequence[str], n_repeats: int) -> float:
    """Lab hours of ``n_repeats`` repeats with ``changed`` settings changed from a measured condition:
    the declared settings' change hours plus the repeats at the largest repeat hours among them
    (a setting that is not declared, or a measured condition, costs the experiment's repeat)."""
    declared = {s.name: s for s in lab_settings(experiment)}
    covered = {a for k in changed if k in declared for a in declared[k].also_scaled}  # come with another change
    parts = [declared[k] for k in changed if k in declared and k not in covered]
    undeclared = [k for k in changed if k not in declared and k not in covered]
    per_repeat = [s.repeat_hours for s in parts] + ([lab_effort(experiment).repeat_hours] if undeclared or not parts
                                                    else [])
    return round(sum(s.change_hours for s in parts) + n_repeats * max(per_repeat), 3)


def lab_hours(experiment: str, condition: Mapping[str, Any], measured: Sequence[Mapping[str, Any]], n_repeats: int,
              scale: str = "paper", experiment_settings: Mapping[str, Any] | None = None) -> float:
    """Lab hours [h] of ``n_repeats`` repeats of ``experiment`` at ``condition``, given the conditions
    of that experiment the lab has ``measured`` (none: the apparatus is set up first). The cheapest
    route from any measured condition counts."""
    if experiment not in EXPERIMENTS:
        raise ConfigError(f"unknown experiment {experiment!r}; the DEM can run {sorted(EXPERIMENTS)}")
    effort = lab_effort(experiment)
    if not measured:
        return round(effort.setup_hours + n_repeats * effort.repeat_hours, 3)
    frame = _Frame(experiment, scale, experiment_settings or {})
    return min(_change_hours(experiment, frame.changed(condition, m), n_repeats) for m in measured)


# ---------------------------------------------------------------------------- enumeration
@dataclass
class _Measured:
    """A measured condition of one experiment: its settings, name and measured quantities."""

    condition: dict[str, Any]
    name: str
    quantities: list[str] = field(default_factory=list)


def _condition_name(key: str, index: int) -> str:
    parts = key.split("/")
    name = parts[1] if len(parts) == 3 else ""
    return name if name and not any(ch.isspace() for ch in name) else f"condition{index + 1}"


def _measured_conditions(observables: Sequence[Any], frames: Mapping[str, _Frame]) -> dict[str, dict[str, _Measured]]:
    """Per experiment, its measured conditions by canonical settings, in the order first measured."""
    out: dict[str, dict[str, _Measured]] = {}
    for o in observables:
        if o.experiment not in frames:
            continue
        cond = dict(o.condition)
        per = out.setdefault(o.experiment, {})
        c = frames[o.experiment].canonical(cond)
        if c not in per:
            per[c] = _Measured(cond, _condition_name(o.key, len(per)))
        if o.quantity not in per[c].quantities:
            per[c].quantities.append(o.quantity)
    return out


def _context(frame: _Frame, m: _Measured, siblings: Sequence[_Measured]) -> str:
    """Words naming measured condition ``m`` among its experiment's others (e.g. ``"at rpm 15"``)."""
    if len(siblings) < 2:
        return ""
    keys = sorted({k for s in siblings for k in s.condition})
    differ = [k for k in keys if len({json.dumps(_plain(frame.value(s.condition, k))) for s in siblings}) > 1]
    return " at " + ", ".join(f"{k} {_text(frame.value(m.condition, k))}" for k in differ) if differ else ""


def _key(experiment: str, name: str, quantity: str) -> str:
    return f"{experiment}/{name}/{quantity}"


def _select(candidates: list[tuple[tuple[str, str], ProposedCondition]], cap: int
            ) -> tuple[list[ProposedCondition], list[ProposedCondition]]:
    """Keep at most ``cap`` candidates: groups (experiment, setting) in order of their cheapest lab
    effort, taken in turns (each group's first before any group's second). Returns (kept, dropped)."""
    groups: dict[tuple[str, str], list[ProposedCondition]] = {}
    for g, c in candidates:
        groups.setdefault(g, []).append(c)
    order = sorted(groups, key=lambda g: min(c.lab_hours for c in groups[g]))  # stable: first seen first
    turns: list[ProposedCondition] = []
    for k in range(max((len(v) for v in groups.values()), default=0)):
        turns += [groups[g][k] for g in order if k < len(groups[g])]
    return turns[:cap], turns[cap:]


def enumerate_proposals(observables: Sequence[Any], scale: str = "paper",
                        experiment_settings: Mapping[str, Mapping[str, Any]] | None = None,
                        max_conditions: int = DEFAULT_MAX_PROPOSED_CONDITIONS, n_repeats: int = 3,
                        check: Callable[[str, Mapping[str, Any]], None] | None = None) -> ProposalPlan:
    """Every condition a lab can reach from the measured ``observables`` (module docstring), bounded.

    observables : the measured observables (``key``, ``experiment``, ``quantity``, ``condition``);
        keys ``experiment/condition/quantity`` name the conditions.
    scale, experiment_settings : as the forward model runs the experiments (a setting a condition
        does not give takes the value these give).
    max_conditions : new conditions (DEM worlds of their own) kept at most (>= 0).
    n_repeats : lab repeats per proposal (its effort and expected standard error).
    check : called with (experiment, settings) of every new condition; a ConfigError it raises (a
        fill the machine cannot hold) leaves the condition out, with the error as the reason.
    """
    if isinstance(max_conditions, bool) or not isinstance(max_conditions, int) or max_conditions < 0:
        raise ConfigError(f"max_proposed_conditions must be an integer >= 0, got {max_conditions!r}")
    if isinstance(n_repeats, bool) or not isinstance(n_repeats, int) or n_repeats < 1:
        raise ConfigError(f"proposal repeats must be an integer >= 1, got {n_repeats!r}")
    settings = {k: dict(v) for k, v in (experiment_settings or {}).items()}
    dropped: list[DroppedCondition] = []
    frames: dict[str, _Frame] = {}
    for name in EXPERIMENTS:
        try:
            frames[name] = _Frame(name, scale, settings.get(name, {}))
        except ConfigError as exc:
            dropped.append(DroppedCondition(name, {}, "every condition", None, f"the experiment refuses its settings: {exc}"))
    measured = _measured_conditions(observables, frames)
    seen = {(e, c) for e, per in measured.items() for c in per}

    def refused(experiment: str, cond: Mapping[str, Any]) -> str | None:
        """Why the condition cannot be simulated (None: it can)."""
        try:
            frames[experiment].build({k: v for k, v in cond.items()})
            if check is not None:
                check(experiment, dict(cond))
        except ConfigError as exc:
            return str(exc)
        return None

    free: list[ProposedCondition] = []
    candidates: list[tuple[tuple[str, str], ProposedCondition]] = []
    for experiment, frame in frames.items():
        cls = EXPERIMENTS[experiment]
        quantities = tuple(cls.OBSERVABLES)
        effort = lab_effort(experiment)
        if experiment not in measured:  # not measured: the standard set-up
            hours = effort.setup_hours + n_repeats * effort.repeat_hours
            words = "its standard set-up (not measured yet)"
            why = refused(experiment, {})
            if why is not None:
                dropped.append(DroppedCondition(experiment, {}, words, hours, f"cannot be simulated: {why}"))
            else:
                candidates.append(((experiment, ""), ProposedCondition(experiment, {}, None, words, hours, True,
                                                                       quantities, "standard")))
            continue
        conditions = list(measured[experiment].values())
        for m in conditions:
            rest = tuple(q for q in quantities if q not in m.quantities)
            if rest:
                free.append(ProposedCondition(experiment, m.condition, None,
                                              f"the measured condition{_context(frame, m, conditions) or ' ' + m.name}",
                                              n_repeats * effort.repeat_hours, False, rest, m.name))
        for m in conditions:
            where = _context(frame, m, conditions)
            for s in lab_settings(experiment):
                old = frame.value(m.condition, s.name)
                if not isinstance(old, (int, float)) or isinstance(old, bool) or not math.isfinite(float(old)):
                    continue
                for factor, value in s.values(float(old)):
                    cond = {**m.condition, s.name: value}
                    for other in s.also_scaled:
                        v = frame.value(m.condition, other)
                        cond[other] = (tuple(round_3(x * factor) for x in v) if isinstance(v, (tuple, list))
                                       else round_3(float(v) * factor))
                    words = f"{s.words} {_with_unit(value, s.unit)} (measured: {_with_unit(old, s.unit)}{where})"
                    c = frame.canonical(cond)
                    if (experiment, c) in seen:
                        continue
                    seen.add((experiment, c))
                    hours = s.hours(n_repeats)
                    why = refused(experiment, cond)
                    if why is not None:
                        dropped.append(DroppedCondition(experiment, cond, words, hours, f"cannot be simulated: {why}"))
                        continue
                    candidates.append(((experiment, s.name), ProposedCondition(
                        experiment, cond, s.name, words, hours, True, quantities, f"{m.name}+{s.name}={value:g}")))
    kept, over = _select(candidates, max_conditions)
    dropped += [DroppedCondition(c.experiment, c.settings, c.words, c.lab_hours,
                                 f"beyond the {max_conditions} new conditions forecast (max_proposed_conditions); "
                                 "cheaper settings, and each setting once, came first") for c in over]
    taken = {o.key for o in observables}
    proposals = []
    for c in free + kept:
        unit_of = EXPERIMENTS[c.experiment].OBSERVABLES
        for q in c.quantities:
            key = _key(c.experiment, c.name, q)
            if key in taken:  # a measured key of another condition: name this one apart
                key = _key(c.experiment, f"proposed-{c.name}", q)
            taken.add(key)
            proposals.append(ProposedMeasurement(
                key, c.experiment, q, unit_of[q], dict(c.settings),
                f"{c.experiment} {q.replace('_', ' ')} at {c.words}", None, n_repeats, lab_hours=c.lab_hours))
    return ProposalPlan(tuple(proposals), tuple(free + kept), tuple(dropped), max_conditions)
