"""warpdem: discrete element method in NVIDIA Warp (CPU and CUDA), many worlds per launch."""
from .builder import ModelBuilder, random_quaternions
from .contact import ContactLaw, ParameterSpec, SubModel, register
from .errors import (ConfigError, ContactOverflowError, OverlapError, StabilityError, StabilityWarning,
                     WarpDEMError)
from .materials import GRAVEL, PLEXIGLAS, STEEL, Material
from .model import Model, State, Wall, WallMotion
from .solver import DEMSolver, SettleReport, Simulation, WallStats, resolve_performance_options
from .shape_families import ShapeFamily, available_shape_families, register_shape_family, shape_family
from .timestep import (check_time_step, hertz_contact_time, hertz_max_overlap, rayleigh_time, time_step_limits,
                       time_step_limits_for)

__version__ = "0.1.0"

__all__ = [
    "ModelBuilder", "Model", "State", "Wall", "WallMotion", "DEMSolver", "SettleReport", "Simulation", "WallStats",
    "resolve_performance_options",
    "ContactLaw", "ParameterSpec", "SubModel", "register", "Material", "GRAVEL", "PLEXIGLAS", "STEEL",
    "ConfigError", "ContactOverflowError", "OverlapError", "StabilityError", "StabilityWarning", "WarpDEMError",
    "check_time_step", "hertz_contact_time", "hertz_max_overlap", "rayleigh_time", "time_step_limits", "time_step_limits_for",
    "random_quaternions", "ShapeFamily", "available_shape_families", "register_shape_family", "shape_family",
]
