"""Calibrate a scene against measured motion: fit isolator (or any continuous) parameters to a test.

A measurement is a time column plus channels. Each channel names where it measures (``cg`` or a point of
interest of the scene), an axis (``x``, ``y``, ``z`` or the rotations ``rx``, ``ry``, ``rz``), a quantity
(``displacement``, ``velocity`` or ``acceleration``) and its units, written as a column header::

    time [s], cg.z.displacement [mm], tool.y.acceleration [g], cg.rx.velocity [mrad/s]

(:func:`read_measurement` reads CSV or netCDF files, :func:`measurement_from_csv` CSV text and
:func:`measurement_from_columns` JSON-like columns.) The parameters to fit are study parameter paths
(:mod:`isolab.studies.inputs.parameters`: ``isolators.f_vertical``, ``isolators.zeta``, ``stages.y.mass``
...) with
bounds. :func:`calibrate` fits them with :func:`scipy.optimize.least_squares` (trust region reflective,
bounded):

- **one engine batch per Jacobian**: the base case and one case per parameter, perturbed by a forward
  difference, go to the engine in one :func:`~isolab.engine.simulate` call;
- **time offset**: the measurement's clock is not the simulation's. The simulated motion at measurement
  time ``t`` is the one at ``t - offset`` (before the simulation's zero the machine is at rest). ``offset``
  is one more fitted parameter; its start is the best of a scan over its bounds with the starting scene,
  and its Jacobian column is the (central-difference) time derivative of the simulated traces;
- **sample rates**: the engine records displacement at its step ``dt``; velocity and acceleration are its
  central first and second differences there (the mean over +- ``dt``), and every channel is interpolated
  linearly onto the measurement's times;
- **acceleration channels**: fitted in acceleration. Accelerometers carry a bias and drift, so acceleration
  channels, measured and simulated alike, have a straight line fitted and removed and pass through the same
  zero-phase band-pass (2nd-order Butterworth run forwards and backwards): high-pass ``highpass`` (default
  0.5 Hz), low-pass ``lowpass`` (default a fifth of the sample rate, at most ``0.03 / dt``: above it the
  engine's step smears a stage's acceleration jumps); 0 switches either off. Applied to both, the filters
  bias nothing. A filtered sample counts as the filter's noise gain of an independent one in the weights
  and the degrees of freedom;
- **noise and weights**: residuals are divided by each channel's sensor noise, stated (``noise``) or
  estimated from the record's own sample-to-sample scatter, then the fit is repeated with each channel's
  noise inflated by its chi-square per degree of freedom and the correlation of its residuals
  (:mod:`.uncertainty`). The covariance ``(J^T J)^-1`` of the Jacobian so weighted gives the 1-sigma
  uncertainty of every fitted value; the chi-square against the noise, with its expected range and a
  verdict, judges the fit (``goodness_of_fit``; ``residual_variance`` is its value per degree of freedom);
- **starts**: the scene's values, and ``starts - 1`` Sobol' points within the bounds on request;
- **identifiability**: a parameter whose Jacobian column is (near) zero per its bounds' width, that is
  (near) collinear with others (the singular values of the column-normalised Jacobian), or whose
  1-sigma uncertainty exceeds a quarter of its bounds' width or half its value is reported as not
  determined by this measurement, with the reason, instead of a number; it keeps the scene's value and
  the others are fitted again without it.

The answer (:class:`Calibration`) holds the fitted values with uncertainties, the misfit (RMS residual)
per channel before (the scene as given, aligned in time by the offset scan) and after, and the calibrated
scene as YAML. Errors in the input raise :class:`~isolab.studies.inputs.definitions.DefinitionError` whose
details name the field (``loc``).

The package's modules, lowest first: :mod:`.measurements` (channels, units, reading and writing
measurements), :mod:`.parameters` (what is fitted, with bounds), :mod:`.model` (the simulated channels),
:mod:`.starts` (where the fit starts), :mod:`.uncertainty` (noise, goodness of fit, honest
uncertainties), :mod:`.scene_text` (the calibrated scene as text), :mod:`.fit` (the least-squares fit
and its answer), :mod:`.requests` (a request body of the API) and :mod:`.jobs` (fits on the workers).
"""

from isolab.studies.answers.calibration.fit import Calibration, ParameterFit, calibrate
from isolab.studies.answers.calibration.measurements import (
    Channel,
    Measurement,
    measurement_csv,
    measurement_from_columns,
    measurement_from_csv,
    measurement_from_netcdf,
    parse_channel,
    parse_header,
    read_measurement,
)
from isolab.studies.answers.calibration.model import synthetic_measurement
from isolab.studies.answers.calibration.parameters import FitSpec, parse_fit, to_si_loc
from isolab.studies.answers.calibration.requests import calibrate_request, request_measurement

__all__ = [
    "Calibration",
    "Channel",
    "FitSpec",
    "Measurement",
    "ParameterFit",
    "calibrate",
    "calibrate_request",
    "measurement_csv",
    "measurement_from_columns",
    "measurement_from_csv",
    "measurement_from_netcdf",
    "parse_channel",
    "parse_fit",
    "parse_header",
    "read_measurement",
    "request_measurement",
    "synthetic_measurement",
    "to_si_loc",
]
