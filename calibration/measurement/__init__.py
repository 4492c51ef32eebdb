"""Angles of repose from particle data or pictures (engine independent).

Definitions follow /work/shared/spec/experiments.md (A baffle box, B drum,
C hollow cylinder, Images) and the seed paper's Section 2.1.2 / Tables 1, 10.

- :mod:`.profiles`: angles from particle centres (N, 3) and radii (m).
- :mod:`.images`: OpenCV pipeline for photographs and drum videos.
- :mod:`.render`: camera-like side views of particles; synthetic test piles.
- :mod:`.records`: measurement files (YAML/JSON) with repeats and statistics.
- :mod:`.cli`: ``warpdem measure``.
"""

from .errors import MeasurementError, MeasurementFileError
from .images import (
    ImageMeasurement,
    VideoMeasurement,
    measure_image,
    video_frame_indices,
    video_frames_for_revolutions,
)
from .profiles import (
    CylinderPileResult,
    DrumResult,
    LineFit,
    ProfileFit,
    SurfaceProfile,
    baffle_static_angle,
    bulk_density,
    cylinder_pile_angle,
    drum_dynamic_angle,
    fit_line,
    mean_surface_height,
    revolution_snapshot_times,
    slope_to_angle_deg,
    surface_profile,
)
from .records import (
    AngleStats,
    ConditionRecord,
    ExperimentRecord,
    MeasurementFile,
    load_measurements,
    parse_measurements,
)
from .render import RenderedView, render_side_view, synthetic_pile, synthetic_slope_image

__all__ = [
    "MeasurementError",
    "MeasurementFileError",
    # profiles
    "LineFit",
    "SurfaceProfile",
    "ProfileFit",
    "DrumResult",
    "CylinderPileResult",
    "fit_line",
    "slope_to_angle_deg",
    "surface_profile",
    "mean_surface_height",
    "baffle_static_angle",
    "bulk_density",
    "drum_dynamic_angle",
    "revolution_snapshot_times",
    "cylinder_pile_angle",
    # images
    "ImageMeasurement",
    "VideoMeasurement",
    "measure_image",
    "video_frame_indices",
    "video_frames_for_revolutions",
    # render
    "RenderedView",
    "render_side_view",
    "synthetic_pile",
    "synthetic_slope_image",
    # records
    "AngleStats",
    "ConditionRecord",
    "ExperimentRecord",
    "MeasurementFile",
    "load_measurements",
    "parse_measurements",
]
