"""Angles of repose from particle data or pictures (engine independent).

Definitions follow docs/experiments.md (A baffle box, B drum,
C hollow cylinder, Images) and the seed paper's Section 2.1.2 / Tables 1, 10.

- :mod:`.profiles`: angles from particle centres (N, 3) and radii (m).
- :mod:`.images`: OpenCV pipeline for photographs and drum videos.
- :mod:`.render`: camera-like side views of particles; synthetic test piles.
- :mod:`.records`: measurement files (YAML/JSON; versions 1 and 2) with repeats, protocol
  settings and statistics; plain observation records; the version-2 writer.
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
    FORMAT_V1,
    FORMAT_V2,
    NO_PILE_LIMIT_DEG,
    QUANTITY_UNITS,
    AngleStats,
    ConditionRecord,
    ExperimentRecord,
    MeasurementFile,
    ObservableRecord,
    ObservationRecord,
    check_settings,
    load_measurements,
    measurements_v2_mapping,
    parse_measurements,
    protocol_settings,
    unreported_observables,
    write_measurements_v2,
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
    "FORMAT_V1",
    "FORMAT_V2",
    "NO_PILE_LIMIT_DEG",
    "QUANTITY_UNITS",
    "ObservableRecord",
    "ObservationRecord",
    "check_settings",
    "protocol_settings",
    "unreported_observables",
    "measurements_v2_mapping",
    "write_measurements_v2",
]
