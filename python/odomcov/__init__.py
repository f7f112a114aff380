"""odomcov: how far to trust the wheel odometry of a two-wheel robot.

The closed-form covariance of odometry error [Kleeman95, Chong97], its Monte-Carlo check, and
the tools that set a model against measured runs. Frames: poses (x, y, theta) in the start
frame, theta counter-clockwise; errors are true - odometry; metres and radians. See
docs/library.md in the odomcov repository.
"""
from ._odomcov import (  # noqa: F401
    InputError,
    OdometryCovariance,
    OdometryStep,
    Suite,
    arc_covariance,
    arc_displacement,
    arc_transition,
    calibrate,
    compare,
    diagnose,
    fit,
    load_suite,
    predict,
    simulate,
    tangential_to_world,
    theory,
)
